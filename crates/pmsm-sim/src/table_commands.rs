//! The table commands of `pmsm-sim` (`faults`, `suite`, `low-speed`, `identify`): run, print the Markdown,
//! write `<stem>.md` and `<stem>.json`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use pmsm_sim::SimError;
use pmsm_sim::analysis::suite::{SuiteMotor, SuiteOptions, run_suite, run_suite_motors};
use pmsm_sim::output::file::write_bytes;
use pmsm_sim::output::mcap::LogOptions;

use crate::{dir_name, load, out_err};

/// `pmsm-sim faults` (module `pmsm_sim::analysis::fault_suite`).
pub(crate) fn faults_command(
    out: &Path,
    t_fault_s: f64,
    t_end_s: f64,
) -> Result<ExitCode, SimError> {
    use pmsm_sim::analysis::fault_suite::{SuiteOptions, markdown, run_suite};
    let opts = SuiteOptions { t_fault_s, t_end_s };
    let results = run_suite(&opts)?;
    let md = markdown(&results, &opts);
    std::fs::create_dir_all(out).map_err(|e| out_err(out, e))?;
    let path = out.join("faults.md");
    write_bytes(&path, md.as_bytes())?;
    print!("{md}");
    println!("\nwritten to {}", path.display());
    let unexpected: Vec<&str> = results
        .iter()
        .filter(|r| !r.as_expected)
        .map(|r| r.name)
        .collect();
    if unexpected.is_empty() {
        return Ok(ExitCode::SUCCESS);
    }
    eprintln!(
        "pmsm-sim: {} of {} fault rows not as expected: {}",
        unexpected.len(),
        results.len(),
        unexpected.join("; ")
    );
    Ok(ExitCode::FAILURE)
}

/// The `--motor` list with repeats dropped, first occurrences kept in order.
pub(crate) fn dedup(motors: &[SuiteMotor]) -> Vec<SuiteMotor> {
    let mut out: Vec<SuiteMotor> = Vec::with_capacity(motors.len());
    for &m in motors {
        if !out.contains(&m) {
            out.push(m);
        }
    }
    out
}

/// A `--motor` name of `pmsm-sim suite`.
pub(crate) fn parse_suite_motor(name: &str) -> Result<SuiteMotor, String> {
    SuiteMotor::from_name(name).ok_or_else(|| {
        let known: Vec<_> = SuiteMotor::ALL.iter().map(|m| m.name()).collect();
        format!("unknown motor `{name}` (known: {})", known.join(", "))
    })
}

/// `pmsm-sim suite`: runs the suite, prints the markdown tables, writes `suite.md` and
/// `suite.json` to `out`. Exit code 1 when a goal or limit fails that is no documented known
/// limit (`pmsm_sim::analysis::suite`, "Known limits"; the tables name those), else 0.
pub(crate) fn suite(
    opts: SuiteOptions,
    motors: &[SuiteMotor],
    out: &Path,
) -> Result<ExitCode, SimError> {
    let report = if motors.is_empty() {
        run_suite(&opts)?
    } else {
        run_suite_motors(&opts, &dedup(motors))?
    };
    write_table(out, "suite", &report.to_markdown(), &report)?;
    let failed: Vec<String> = report
        .unexpected_failures()
        .map(|c| format!("{} ({}, {})", c.name, c.motor.name(), c.row))
        .chain(
            report
                .saturated
                .checks
                .iter()
                .filter(|c| !c.pass)
                .map(|c| format!("{} ({})", c.name, c.motor)),
        )
        .collect();
    if failed.is_empty() {
        return Ok(ExitCode::SUCCESS);
    }
    eprintln!(
        "pmsm-sim: {} check(s) failed: {}",
        failed.len(),
        failed.join("; ")
    );
    Ok(ExitCode::FAILURE)
}

/// A table command's outputs: the Markdown `md` printed and written to `out/{stem}.md`, and
/// `value` as pretty JSON to `out/{stem}.json`.
pub(crate) fn write_table(
    out: &Path,
    stem: &str,
    md: &str,
    value: &impl serde::Serialize,
) -> Result<ExitCode, SimError> {
    print!("{md}");
    std::fs::create_dir_all(out).map_err(|e| out_err(out, e))?;
    let md_path = out.join(format!("{stem}.md"));
    write_bytes(&md_path, md.as_bytes())?;
    let json_path = out.join(format!("{stem}.json"));
    let json = serde_json::to_string_pretty(value).map_err(|e| out_err(&json_path, e))?;
    write_bytes(&json_path, format!("{json}\n").as_bytes())?;
    println!("\noutputs: {} {}", md_path.display(), json_path.display());
    Ok(ExitCode::SUCCESS)
}

/// `pmsm-sim low-speed` (module `pmsm_sim::analysis::low_speed`): the table, printed and written to
/// `out`. A missed goal is a result, not an error.
pub(crate) fn low_speed_command(
    motors: &[SuiteMotor],
    hold: f64,
    out: &Path,
) -> Result<ExitCode, SimError> {
    use pmsm_sim::analysis::low_speed::{SPEEDS_PCT, run_motor, to_markdown};
    if !(hold.is_finite() && hold > 0.0) {
        return Err(SimError::Scenario {
            file: "command line".into(),
            field: "--hold".into(),
            problem: format!("must be a positive time in s, is {hold}"),
        });
    }
    let motors = if motors.is_empty() {
        SuiteMotor::SURFACE.to_vec()
    } else {
        dedup(motors)
    };
    let mut rows = vec![];
    for &m in &motors {
        rows.push(run_motor(m, &SPEEDS_PCT, hold)?);
    }
    write_table(out, "lowspeed", &to_markdown(&rows), &rows)
}

/// `pmsm-sim identify`: the report (table or JSON), the log, the plot and, with the flux-map
/// step, its table and plot.
pub(crate) fn identify_command(
    what: Option<&str>,
    json: bool,
    seed: Option<u64>,
    out: Option<PathBuf>,
    log: LogOptions,
    flux_map: Option<Option<f64>>,
) -> Result<ExitCode, SimError> {
    use pmsm_sim::analysis::identify::{IdentifyOptions, identify, output_paths, table};
    let scenario = load(what.unwrap_or("default"))?;
    let dir = out.unwrap_or_else(|| Path::new("out").join(dir_name(&scenario.name)));
    std::fs::create_dir_all(&dir).map_err(|e| out_err(&dir, e))?;
    let (mcap, svg) = output_paths(&dir);
    let opts = IdentifyOptions {
        mcap: Some(mcap),
        svg: Some(svg),
        seed,
        log,
        flux_map_a: flux_map.map(|i| i.unwrap_or(0.85 * scenario.controller.current_limit_a)),
    };
    let r = identify(&scenario, &opts)?;
    let map_files = match &r.flux_map {
        Some(m) if m.ok => {
            let md = dir.join("identify-flux-map.md");
            let svg = dir.join("identify-flux-map.svg");
            std::fs::write(&md, m.table()).map_err(|e| out_err(&md, e))?;
            m.write_svg(
                &svg,
                &format!("pmsm-sim identify --flux-map: {}", scenario.name),
            )?;
            Some((md, svg))
        }
        _ => None,
    };
    if json {
        let text = pmsm_sim::analysis::identify::json(&r).map_err(|e| out_err(&dir, e))?;
        println!("{text}");
    } else {
        print!("{}", table(&r));
        if let Some(m) = &r.flux_map {
            print!("{}", m.table());
        }
    }
    if let Some((md, svg)) = map_files {
        eprintln!("flux map: {} {}", md.display(), svg.display());
    }
    let map_ok = r.flux_map.as_ref().is_none_or(|m| m.ok);
    Ok(if r.ok && map_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

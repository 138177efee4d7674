//! Human- and machine-readable reports of [`RunMetrics`].

use core::fmt::Write as _;

use crate::output::metrics::{
    CONVERGED_DEG, LOW_SPEED_FRACTION, ObserverMetrics, RAMP_SETTLE_S, RunMetrics, SETTLE_S,
};

/// The head of one block of [`table`] after a blank line: its title with the `unit` and
/// `value` column heads, an optional note line, and the rule.
fn block_header(out: &mut String, title: &str, note: Option<&str>, width: usize) {
    let _ = writeln!(out);
    let _ = writeln!(out, "{title:<40} {:<10} {:>14}", "unit", "value");
    if let Some(n) = note {
        let _ = writeln!(out, "{n}");
    }
    let _ = writeln!(out, "{}", "-".repeat(width.max(67)));
}

/// The metrics as a plain aligned text table.
pub fn table(m: &RunMetrics) -> String {
    let mut out = String::new();
    // Writing to a String cannot fail; the results are ignored on purpose.
    let _ = writeln!(out, "scenario: {}", m.scenario);
    let _ = writeln!(out, "controller: {}", m.controller);
    if m.end != "completed" {
        let _ = writeln!(out, "RUN STOPPED EARLY: {}", m.end);
    }
    let _ = writeln!(
        out,
        "simulated {:.3} s ({} periods of {:.1} us) in {:.3} s wall: real-time factor {:.1}",
        m.simulated_s,
        m.periods,
        m.ts_s * 1e6,
        m.wall_time_s,
        m.real_time_factor
    );
    if m.skipped_control_periods > 0 {
        let _ = writeln!(
            out,
            "skipped control periods: {} ({:.2} %)",
            m.skipped_control_periods,
            100.0 * m.skipped_control_periods as f64 / m.periods.max(1) as f64
        );
    }
    let _ = writeln!(
        out,
        "observer window: after convergence (|e_th| < {CONVERGED_DEG} deg for the rest of the run), \
         |w_e| >= {:.0} % of rated ({:.1} rad/s el.)",
        LOW_SPEED_FRACTION * 100.0,
        LOW_SPEED_FRACTION * m.rated_omega_e_rad_s
    );
    let _ = writeln!(out);

    let mut cols: Vec<(&str, Option<&ObserverMetrics>)> = Vec::with_capacity(3);
    if m.controller_observer.is_some() {
        cols.push(("foc EKF (f32)", m.controller_observer.as_ref()));
    }
    cols.push(("EKF f64 (sim)", m.observer.as_ref()));
    cols.push(("seed filter", m.seed_filter.as_ref()));
    type Row = (&'static str, &'static str, fn(&ObserverMetrics) -> String);
    let rows: [Row; 15] = [
        ("convergence time", "s", |o| {
            o.convergence_time_s
                .map_or_else(|| "never".into(), |t| format!("{t:.4}"))
        }),
        ("window length", "s", |o| format!("{:.4}", o.window_s)),
        ("angle error RMS", "deg el.", |o| {
            format!("{:.3}", o.angle_error_rms_deg)
        }),
        ("angle error max |e|", "deg el.", |o| {
            format!("{:.3}", o.angle_error_max_deg)
        }),
        ("angle error mean (bias)", "deg el.", |o| {
            format!("{:+.3}", o.angle_error_mean_deg)
        }),
        ("speed error RMS", "rad/s el.", |o| {
            format!("{:.3}", o.speed_error_rms_rad_s)
        }),
        ("speed error RMS", "% rated", |o| {
            format!("{:.4}", o.speed_error_rms_pct)
        }),
        ("speed error max |e|", "rad/s el.", |o| {
            format!("{:.3}", o.speed_error_max_rad_s)
        }),
        ("status Tracking in window", "%", |o| {
            format!("{:.1}", o.tracking_pct)
        }),
        ("status Tracking, whole run", "%", |o| {
            format!("{:.1}", o.tracking_run_pct)
        }),
        ("Tracking while >45 deg off", "samples", |o| {
            format!("{}", o.tracking_while_lost)
        }),
        ("NIS mean (2: consistent)", "", |o| {
            format!("{:.2}", o.nis_mean)
        }),
        ("converged at end", "", |o| {
            if o.converged { "yes" } else { "no" }.into()
        }),
        ("psi_f at end vs plant", "%", |o| {
            format!("{:+.2}", o.psi_f_error_end_pct)
        }),
        ("Rs at end vs plant", "%", |o| {
            format!("{:+.2}", o.rs_error_end_pct)
        }),
    ];
    let width = 37 + 15 * cols.len();
    let _ = write!(out, "{:<26} {:<10}", "observer metric", "unit");
    for (name, _) in &cols {
        let _ = write!(out, " {name:>14}");
    }
    let _ = writeln!(out);
    let _ = writeln!(out, "{}", "-".repeat(width));
    for (name, unit, f) in rows {
        let _ = write!(out, "{name:<26} {unit:<10}");
        for (_, c) in &cols {
            let _ = write!(out, " {:>14}", c.map_or_else(|| "-".into(), f));
        }
        let _ = writeln!(out);
    }
    if let Some(why) = &m.seed_filter_failure {
        let _ = writeln!(out, "seed filter dropped at {why}");
    }
    if let Some(c) = &m.controller_observer_closed_loop {
        let note = format!(
            "(the loops run on its angle; |w_e| >= {:.0} % of rated)",
            LOW_SPEED_FRACTION * 100.0
        );
        block_header(&mut out, "foc EKF after the hand-over", Some(&note), width);
        for (name, unit, v) in [
            ("window length", "s", format!("{:.4}", c.window_s)),
            (
                "angle error RMS",
                "deg el.",
                format!("{:.3}", c.angle_error_rms_deg),
            ),
            (
                "angle error max |e|",
                "deg el.",
                format!("{:.3}", c.angle_error_max_deg),
            ),
            (
                "angle error mean (bias)",
                "deg el.",
                format!("{:+.3}", c.angle_error_mean_deg),
            ),
            (
                "speed error RMS",
                "rad/s el.",
                format!("{:.3}", c.speed_error_rms_rad_s),
            ),
            (
                "speed error max |e|",
                "rad/s el.",
                format!("{:.3}", c.speed_error_max_rad_s),
            ),
        ] {
            let _ = writeln!(out, "{name:<40} {unit:<10} {v:>14}");
        }
    }
    let d = &m.drive;
    block_header(&mut out, "drive", None, width);
    let opt = |x: f64, prec: usize| {
        if x.is_finite() {
            format!("{x:.prec$}")
        } else {
            "-".into()
        }
    };
    let settled = format!("settled (ref const., no load step {SETTLE_S} s)");
    let drive_rows = [
        (
            "time to closed loop (hand-over)",
            "s",
            d.closed_loop_time_s
                .map_or_else(|| "never".into(), |t| format!("{t:.4}")),
        ),
        (
            "in closed loop",
            "% periods",
            format!("{:.1}", d.closed_loop_pct),
        ),
        (
            "closed-loop exits (I/f, fall-back)",
            "",
            d.closed_loop_exits.to_string(),
        ),
        (
            "fault",
            "",
            d.fault.clone().unwrap_or_else(|| "none".into()),
        ),
        (settled.as_str(), "s", format!("{:.3}", d.settled_s)),
        (
            "speed error settled: RMS",
            "rpm",
            opt(d.speed_error_settled_rms_rpm, 2),
        ),
        (
            "speed error settled: mean",
            "rpm",
            opt(d.speed_error_settled_mean_rpm, 2),
        ),
        (
            "speed error settled: max |e|",
            "rpm",
            opt(d.speed_error_settled_max_rpm, 2),
        ),
        (
            "max |speed ref - speed| (whole run)",
            "rpm",
            format!("{:.1}", d.max_speed_tracking_error_rpm),
        ),
        ("peak current |i|", "A", format!("{:.3}", d.peak_current_a)),
        (
            "i_q tracking error RMS",
            "A",
            format!("{:.4}", d.iq_tracking_error_rms_a),
        ),
        ("final speed", "rpm", format!("{:.1}", d.final_speed_rpm)),
        (
            "voltage vector limited",
            "% periods",
            format!("{:.2}", d.voltage_limited_pct),
        ),
    ];
    for (name, unit, v) in drive_rows {
        let _ = writeln!(out, "{name:<40} {unit:<10} {v:>14}");
    }
    if let Some(st) = &m.startup {
        block_header(&mut out, "start-up", None, width);
        let both = |rpm: f64, pct: f64| {
            if rpm.is_finite() {
                format!("{rpm:.1} ({pct:.2} %)")
            } else {
                "-".into()
            }
        };
        let ramp_window = format!("worst |speed - ramp| from align + {RAMP_SETTLE_S} s");
        let rows = [
            (
                "alignment ends",
                "s",
                st.align_end_s
                    .map_or_else(|| "-".into(), |t| format!("{t:.4}")),
            ),
            (
                "worst backward speed (% rated)",
                "rpm",
                both(st.backward_speed_max_rpm, st.backward_speed_max_pct),
            ),
            (
                ramp_window.as_str(),
                "rpm",
                both(st.ramp_deviation_max_rpm, st.ramp_deviation_max_pct),
            ),
            (
                "hand-over",
                "s",
                st.handover_s
                    .map_or_else(|| "never".into(), |t| format!("{t:.4}")),
            ),
            (
                "hand-over ramp speed (% rated)",
                "rpm",
                both(st.handover_speed_rpm, st.handover_speed_pct),
            ),
            (
                "true speed at the hand-over",
                "rpm",
                opt(st.handover_true_speed_rpm, 1),
            ),
        ];
        for (name, unit, v) in rows {
            let _ = writeln!(out, "{name:<40} {unit:<10} {v:>14}");
        }
    }
    if let Some(r) = &m.reversal {
        block_header(&mut out, "speed reversal", None, width);
        let rows = [
            ("reversals", "", format!("{}", r.count)),
            ("first one starts", "s", format!("{:.4}", r.first_start_s)),
            (
                "time outside closed loop (worst)",
                "ms",
                format!("{:.1}", 1e3 * r.outside_closed_loop_max_s),
            ),
            ("closed-loop exits", "", format!("{}", r.closed_loop_exits)),
            (
                "worst |speed ref - speed| (% rated)",
                "rpm",
                format!(
                    "{:.1} ({:.2} %)",
                    r.tracking_error_max_rpm, r.tracking_error_max_pct
                ),
            ),
        ];
        for (name, unit, v) in rows {
            let _ = writeln!(out, "{name:<40} {unit:<10} {v:>14}");
        }
    }
    out
}

/// The metrics as pretty-printed JSON (NaN, for an empty window, becomes `null`).
pub fn json(m: &RunMetrics) -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(m)
}

/// The fields of [`RunMetrics`] that measure the wall clock (they differ between identical
/// runs): `wall_time_s`, `real_time_factor`.
pub const TIMING_FIELDS: [&str; 2] = ["wall_time_s", "real_time_factor"];

/// The metrics split for the run's files: `(metrics.json, timing.json)`. The first is
/// [`json`] without the [`TIMING_FIELDS`] (so identical runs give identical bytes), the
/// second holds those, with the scenario's name and the simulated time they refer to.
pub fn json_split(m: &RunMetrics) -> Result<(String, String), serde_json::Error> {
    let full = json(m)?;
    // Pretty-printing puts each top-level field on its own line, indented by two spaces;
    // neither timing field is the last, so the commas stay right.
    let metrics: Vec<&str> = full
        .lines()
        .filter(|l| {
            !TIMING_FIELDS
                .iter()
                .any(|f| l.starts_with(&format!("  \"{f}\": ")))
        })
        .collect();
    let timing = serde_json::to_string_pretty(&serde_json::json!({
        "scenario": m.scenario,
        "simulated_s": m.simulated_s,
        "wall_time_s": m.wall_time_s,
        "real_time_factor": m.real_time_factor,
    }))?;
    Ok((metrics.join("\n"), timing))
}

//! Human- and machine-readable reports of [`RunMetrics`].

use core::fmt::Write as _;

use crate::metrics::{CONVERGED_DEG, LOW_SPEED_FRACTION, ObserverMetrics, RunMetrics};

/// The metrics as a plain aligned text table.
pub fn table(m: &RunMetrics) -> String {
    let mut out = String::new();
    // Writing to a String cannot fail; the results are ignored on purpose.
    let _ = writeln!(out, "scenario: {}", m.scenario);
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
    let _ = writeln!(
        out,
        "observer window: after convergence (|e_th| < {CONVERGED_DEG} deg for the rest of the run), \
         |w_e| >= {:.0} % of rated ({:.1} rad/s el.)",
        LOW_SPEED_FRACTION * 100.0,
        LOW_SPEED_FRACTION * m.rated_omega_e_rad_s
    );
    let _ = writeln!(out);

    let cols: [(&str, Option<&ObserverMetrics>); 2] = [
        ("EKF (default)", m.observer.as_ref()),
        ("seed filter", m.seed_filter.as_ref()),
    ];
    type Row = (&'static str, &'static str, fn(&ObserverMetrics) -> String);
    let rows: [Row; 11] = [
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
        ("NIS mean (2: consistent)", "", |o| {
            format!("{:.2}", o.nis_mean)
        }),
        ("converged at end", "", |o| {
            if o.converged { "yes" } else { "no" }.into()
        }),
    ];
    let _ = writeln!(
        out,
        "{:<26} {:<10} {:>14} {:>14}",
        "observer metric", "unit", cols[0].0, cols[1].0
    );
    let _ = writeln!(out, "{}", "-".repeat(67));
    for (name, unit, f) in rows {
        let cell = |c: Option<&ObserverMetrics>| c.map_or_else(|| "-".into(), f);
        let _ = writeln!(
            out,
            "{name:<26} {unit:<10} {:>14} {:>14}",
            cell(cols[0].1),
            cell(cols[1].1)
        );
    }
    if let Some(why) = &m.seed_filter_failure {
        let _ = writeln!(out, "seed filter dropped at {why}");
    }
    let _ = writeln!(out);
    let d = &m.drive;
    let _ = writeln!(out, "{:<37} {:<10} {:>14}", "drive", "unit", "value");
    let _ = writeln!(out, "{}", "-".repeat(67));
    let drive_rows = [
        ("peak current |i|", "A", format!("{:.3}", d.peak_current_a)),
        (
            "max |speed ref - speed|",
            "rpm",
            format!("{:.1}", d.max_speed_tracking_error_rpm),
        ),
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
        let _ = writeln!(out, "{name:<37} {unit:<10} {v:>14}");
    }
    out
}

/// The metrics as pretty-printed JSON (NaN, for an empty window, becomes `null`).
pub fn json(m: &RunMetrics) -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(m)
}

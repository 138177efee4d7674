//! What the start-up is doing, in words: the controller's state changes of a run (from the
//! per-period record's `control.telemetry.state` and `fault`) as a short timeline that
//! `pmsm-sim run` prints on stderr after the run.
//!
//! Each line is a time and what happened: the alignment's start (with its current) and end,
//! the I/f ramp (its acceleration and target, the hand-over speed), the hand-over to the
//! observer (ramp and true speed), closed loop, each exit from closed loop and a fault. An
//! exit from closed loop is called planned when the controller's (slewed) speed reference
//! was below foc's exit speed (`exit_speed_ratio` of the
//! hand-over speed), and a fall-back on an observer loss otherwise (the health check that
//! failed is not in the record). The summary ends with the time to closed loop, its share
//! of the run and the settings that set it (`align_time_s`, the I/f ramp), with where they
//! come from (the scenario or foc's defaults).

use std::fmt::Write;

use super::SampleSink;
use super::record::Sample;
use crate::scenario::{RPM_PER_RAD_S, Scenario, StartupTiming};

/// Lines printed at most; the rest are counted.
const MAX_LINES: usize = 12;

/// foc's start-up settings, in the units printed.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Settings {
    align_time_s: f64,
    align_from: &'static str,
    align_current_a: f64,
    kick_rpm: f64,
    accel_rpm_s: f64,
    accel_from: &'static str,
    handover_rpm: f64,
    exit_rpm: f64,
}

/// The state changes of one run (a [`SampleSink`]), and their summary.
#[derive(Clone, Debug, PartialEq)]
pub struct StartupLog {
    settings: Option<Settings>,
    duration_s: f64,
    state: &'static str,
    fault: bool,
    prev_ref_rpm: Option<f64>,
    closed_at: Option<f64>,
    align_start: Option<f64>,
    lines: Vec<String>,
    more: usize,
}

impl StartupLog {
    /// A log for a run of `sc` (foc's settings from `Scenario::foc_config`).
    pub fn new(sc: &Scenario) -> Self {
        let settings = sc.foc_config().ok().map(|c| {
            let st = c.startup;
            let to_rpm = |w_e: f32| f64::from(w_e) / sc.motor.p() * RPM_PER_RAD_S;
            let foc = sc.controller.foc.unwrap_or_default();
            let motor = foc.startup_timing == StartupTiming::Motor;
            let from = |given: bool, default: &'static str| match (given, motor) {
                (true, _) => "[controller.foc]",
                (false, true) => "from the motor: startup_timing = \"motor\"",
                (false, false) => default,
            };
            Settings {
                align_time_s: f64::from(st.align_time_s),
                align_from: from(foc.align_time_s.is_some(), "foc's default"),
                align_current_a: f64::from(st.align_current_a),
                kick_rpm: to_rpm(st.kick_speed_ratio * st.handover_speed_rad_s),
                accel_rpm_s: to_rpm(st.accel_rad_s2),
                accel_from: from(
                    foc.startup_accel_rpm_per_s.is_some(),
                    "foc's default: the hand-over speed in 0.5 s",
                ),
                handover_rpm: to_rpm(st.handover_speed_rad_s),
                exit_rpm: to_rpm(st.exit_speed_ratio * st.handover_speed_rad_s),
            }
        });
        Self {
            settings,
            duration_s: sc.duration_s,
            state: "idle",
            fault: false,
            prev_ref_rpm: None,
            closed_at: None,
            align_start: None,
            lines: Vec::new(),
            more: 0,
        }
    }

    fn say(&mut self, t_s: f64, what: String) {
        if self.lines.len() < MAX_LINES {
            self.lines.push(format!("  {t_s:>8.4} s  {what}"));
        } else {
            self.more += 1;
        }
    }

    /// Time of the first closed-loop period (`handover` or `closed_loop` for foc,
    /// `sensored`), s.
    pub fn closed_loop_s(&self) -> Option<f64> {
        self.closed_at
    }

    /// The timeline and the time to closed loop (module docs), one line each.
    pub fn summary(&self) -> String {
        let mut out = String::from("start-up and drive states:\n");
        for l in &self.lines {
            let _ = writeln!(out, "{l}");
        }
        if self.more > 0 {
            let _ = writeln!(out, "  ... and {} more state changes", self.more);
        }
        match self.closed_at {
            Some(t) => {
                let _ = write!(
                    out,
                    "  time to closed loop {t:.3} s ({:.0} % of the run): the speed reference \
                     is followed from then on",
                    100.0 * t / self.duration_s.max(f64::MIN_POSITIVE)
                );
            }
            None => {
                let _ = write!(
                    out,
                    "  never in closed loop: the speed reference was not followed"
                );
            }
        }
        if let Some(s) = &self.settings
            && self.align_start.is_some()
        {
            let _ = write!(
                out,
                "\n  set by: align_time_s {:.3} s ({}), I/f ramp {:.0} rpm/s to the hand-over \
                 speed {:.0} rpm ({}; startup_accel_rpm_per_s)",
                s.align_time_s, s.align_from, s.accel_rpm_s, s.handover_rpm, s.accel_from,
            );
            if s.kick_rpm > 0.0 {
                let _ = write!(
                    out,
                    "; the alignment's kick ends it when the rotor is seen moving at {:.1} rpm \
                     (its current rises slowly so that the rotor starts gently; \
                     startup_kick_speed_ratio = 0 holds the vector for align_time_s instead)",
                    s.kick_rpm
                );
            }
        }
        out.push('\n');
        out
    }

    fn change(&mut self, s: &Sample, from: &'static str, to: &'static str) {
        let t = s.t_s;
        let tel = &s.control.telemetry;
        let ramp = tel.speed_ref_rpm.unwrap_or(f64::NAN);
        let set = self.settings;
        let what = match (from, to) {
            (_, "align") => {
                self.align_start = Some(t);
                match set {
                    Some(c) => format!("alignment starts ({:.2} A)", c.align_current_a),
                    None => "alignment starts".into(),
                }
            }
            ("align", "open_loop") => {
                let took = self.align_start.map_or(f64::NAN, |t0| t - t0);
                match set {
                    Some(c) => format!(
                        "alignment ends after {took:.3} s (align_time_s {:.3} s{}); I/f ramp at \
                         {:.0} rpm/s toward the hand-over speed {:.0} rpm",
                        c.align_time_s,
                        if took < 0.98 * c.align_time_s {
                            ": the rotor's motion was read sooner"
                        } else {
                            ""
                        },
                        c.accel_rpm_s,
                        c.handover_rpm
                    ),
                    None => format!("alignment ends after {took:.3} s; I/f ramp"),
                }
            }
            (_, "handover") => format!(
                "hand-over to the observer at {:.0} rpm (ramp; true {:.0} rpm)",
                self.prev_ref_rpm.unwrap_or(ramp).abs(),
                s.truth.speed_rpm
            ),
            ("handover", "closed_loop") => format!(
                "closed loop (speed reference {:.0} rpm)",
                s.control.speed_ref_rpm
            ),
            (_, "sensored") | ("idle", "closed_loop") => {
                "closed loop on the sensor (sensored: no alignment, no I/f)".into()
            }
            ("closed_loop" | "handover", "open_loop") => {
                // foc leaves closed loop on its slewed reference (the last period's).
                let r = self.prev_ref_rpm.unwrap_or(s.control.speed_ref_rpm).abs();
                match set {
                    Some(c) if r < c.exit_rpm => format!(
                        "back to I/f at {:.0} rpm: reference {r:.0} rpm below the exit speed \
                         {:.0} rpm (planned)",
                        s.truth.speed_rpm, c.exit_rpm
                    ),
                    Some(c) => format!(
                        "fall-back to I/f at {:.0} rpm: observer lost (reference {r:.0} rpm, \
                         above the exit speed {:.0} rpm)",
                        s.truth.speed_rpm, c.exit_rpm
                    ),
                    None => format!("left closed loop at {:.0} rpm", s.truth.speed_rpm),
                }
            }
            (_, "fault") => format!(
                "fault: {} at {:.0} rpm; PWM off",
                tel.fault.unwrap_or("unknown"),
                s.truth.speed_rpm
            ),
            (_, "idle") => "idle (PWM off)".into(),
            _ => format!("{from} -> {to}"),
        };
        self.say(t, what);
    }
}

impl SampleSink for StartupLog {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        let tel = &s.control.telemetry;
        let state = tel.state;
        if state != self.state {
            let from = self.state;
            self.state = state;
            self.change(s, from, state);
        }
        if tel.closed_loop && self.closed_at.is_none() {
            self.closed_at = Some(s.t_s);
        }
        if !self.fault
            && state != "fault"
            && let Some(f) = tel.fault
        {
            self.fault = true;
            self.say(s.t_s, format!("fault: {f}"));
        }
        self.fault |= state == "fault";
        self.prev_ref_rpm = tel.speed_ref_rpm;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, state: &'static str, ref_rpm: f64, ramp: Option<f64>) -> Sample {
        let mut s = Sample {
            t_s: t,
            ..Sample::default()
        };
        s.control.speed_ref_rpm = ref_rpm;
        s.control.telemetry.state = state;
        s.control.telemetry.speed_ref_rpm = ramp;
        s.control.telemetry.closed_loop = matches!(state, "handover" | "closed_loop");
        s
    }

    #[test]
    fn state_changes_read_as_a_timeline_with_reasons() {
        let sc = Scenario::default_servo();
        let mut log = StartupLog::new(&sc);
        // The default: align 0.1 s at 2.5 A, 2000 rpm/s; exit at 1.5 % of rated (30 rpm).
        let exit = log.settings.map(|c| c.exit_rpm).unwrap_or_default();
        assert!(exit > 10.0, "{exit}");
        let seq = [
            sample(0.0, "align", 0.0, Some(0.0)),
            sample(0.1, "open_loop", 0.0, Some(0.0)),
            sample(0.15, "open_loop", 500.0, Some(80.0)),
            sample(0.2, "handover", 500.0, Some(90.0)),
            sample(0.22, "closed_loop", 500.0, Some(500.0)),
            // Leaves closed loop with a reference far above the exit speed: a fall-back.
            sample(0.5, "open_loop", 500.0, Some(300.0)),
            sample(0.6, "handover", 500.0, Some(90.0)),
            sample(0.62, "closed_loop", 500.0, Some(500.0)),
            // The reference below the exit speed: planned.
            sample(0.8, "closed_loop", 0.0, Some(0.5 * exit)),
            sample(0.81, "open_loop", 0.0, Some(0.5 * exit)),
        ];
        for s in &seq {
            assert_eq!(log.record(s), Ok(()));
        }
        let mut f = sample(0.9, "fault", 0.0, None);
        f.control.telemetry.fault = Some("over_current");
        assert_eq!(log.record(&f), Ok(()));
        assert_eq!(log.closed_loop_s(), Some(0.2));
        let text = log.summary();
        let planned = format!(
            "0.8100 s  back to I/f at 0 rpm: reference {:.0} rpm below the exit speed {:.0} \
             rpm (planned)",
            0.5 * exit,
            exit
        );
        for part in [
            "0.0000 s  alignment starts (2.50 A)",
            "0.1000 s  alignment ends after 0.100 s (align_time_s 0.100 s); I/f ramp at 2000 rpm/s",
            "0.2000 s  hand-over to the observer at 80 rpm",
            "0.2200 s  closed loop (speed reference 500 rpm)",
            "0.5000 s  fall-back to I/f at 0 rpm: observer lost (reference 500 rpm",
            planned.as_str(),
            "0.9000 s  fault: over_current",
            "time to closed loop 0.200 s (10 % of the run)",
            "align_time_s 0.100 s ([controller.foc]), I/f ramp 2000 rpm/s",
        ] {
            assert!(text.contains(part), "{part:?} missing:\n{text}");
        }
    }

    #[test]
    fn a_run_that_never_closes_its_loop_says_so() {
        let sc = Scenario::default_servo();
        let mut log = StartupLog::new(&sc);
        for k in 0..(MAX_LINES + 5) {
            let st = if k % 2 == 0 { "align" } else { "open_loop" };
            assert_eq!(log.record(&sample(k as f64 * 0.01, st, 0.0, None)), Ok(()));
        }
        let text = log.summary();
        assert!(text.contains("never in closed loop"), "{text}");
        // foc sensored goes from idle straight to closed loop.
        let mut log = StartupLog::new(&sc);
        assert_eq!(
            log.record(&sample(1e-4, "closed_loop", 0.0, Some(0.0))),
            Ok(())
        );
        assert!(
            log.summary()
                .contains("0.0001 s  closed loop on the sensor (sensored: no alignment, no I/f)"),
            "{}",
            log.summary()
        );
        assert!(text.contains("... and 5 more state changes"), "{text}");
    }
}

//! `pmsm_sim::analysis::replay` end to end on logs that parse but are extreme: tiny and huge
//! magnitudes, constant and zero rows, one to three rows, periods at the edges of what the
//! reader takes, motors at the edges of what the motor file takes. Each gives a report and
//! its outputs (MCAP, plot, metrics) or an error, never a panic.

use std::fmt::Write as _;
use std::path::PathBuf;

use pmsm_sim::analysis::replay::{Scaling, parse_csv, parse_motor, replay, write_outputs};
use pmsm_sim::output::mcap::LogOptions;

/// A xorshift generator (deterministic, no dependency).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn pick<T: Copy>(&mut self, v: &[T]) -> T {
        v[(self.next() % v.len() as u64) as usize]
    }
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A value of a random order of magnitude (or zero), either sign.
fn value(rng: &mut Rng, scales: &[f64]) -> f64 {
    let s = rng.pick(scales);
    let v = s * (2.0 * rng.unit() - 1.0);
    if rng.next().is_multiple_of(8) { 0.0 } else { v }
}

#[test]
fn extreme_logs_and_motors_give_a_report_or_an_error() {
    let out = dir("replay-extremes");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let scales = [1e-300, 1e-9, 1e-3, 1.0, 1e3, 1e9, 1e150, 1e300];
    let motors = [
        "rs_ohm = 0.1\nld_h = 2.8e-5\nlq_h = 4.4e-5\npsi_f_wb = 0.0025\npole_pairs = 7\nts_s = 1e-4\n",
        "rs_ohm = 1e-6\nls_h = 1e-7\npsi_f_wb = 1e-6\npole_pairs = 1\nts_s = 1e-5\n",
        "rs_ohm = 100.0\nls_h = 1.0\npsi_f_wb = 10.0\npole_pairs = 50\nts_s = 1e-3\n",
        "rs_ohm = 0.5\nls_h = 1e-3\npsi_f_wb = 0.05\npole_pairs = 4\nts_s = 1e-4\nvoltage_delay_s = -2e-4\ninverter_voltage_v = 100.0\n",
    ];
    let (mut reports, mut errors) = (0, 0);
    for case in 0..160 {
        let text = motors[case % motors.len()];
        let motor = match parse_motor(text, "m.toml") {
            Ok(m) => m,
            Err(e) => {
                errors += 1;
                eprintln!("motor {case}: {e}");
                continue;
            }
        };
        let rows = rng.pick(&[1usize, 2, 3, 50, 400, 3000]);
        let ts = rng.pick(&[1e-4, 1e-9, 1e-3, 0.05]);
        let with_reference = rng.next().is_multiple_of(2);
        let mut csv = String::from("t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a,i_beta_a");
        if with_reference {
            csv.push_str(",theta_ref_rad,omega_ref_rad_s");
        }
        csv.push('\n');
        let constant = rng.next().is_multiple_of(6);
        let (mut t, mut row) = (0.0, [0.0; 4]);
        for k in 0..rows {
            if k == 0 || !constant {
                row = [
                    value(&mut rng, &scales),
                    value(&mut rng, &scales),
                    value(&mut rng, &scales),
                    value(&mut rng, &scales),
                ];
            }
            let dt = ts * rng.pick(&[1.0, 1.0, 1.0, 2.0, 0.5, 1e3]);
            t += dt;
            let _ = write!(
                csv,
                "{t:e},{dt:e},{:e},{:e},{:e},{:e}",
                row[0], row[1], row[2], row[3]
            );
            if with_reference {
                let _ = write!(
                    csv,
                    ",{:e},{:e}",
                    value(&mut rng, &[1.0, 1e3, 1e300]),
                    value(&mut rng, &scales)
                );
            }
            csv.push('\n');
        }
        let log = match parse_csv(csv.as_bytes(), "x.csv", Scaling::Amplitude) {
            Ok(l) => l,
            Err(e) => {
                errors += 1;
                eprintln!("log {case}: {e}");
                continue;
            }
        };
        match replay(&log, &motor, "x") {
            Ok(rep) => {
                let d = out.join(format!("c{case}"));
                match write_outputs(&d, &log, &motor, &rep, LogOptions::default()) {
                    Ok(paths) => {
                        reports += 1;
                        for p in paths {
                            assert!(p.is_file(), "{}", p.display());
                        }
                    }
                    Err(e) => {
                        errors += 1;
                        eprintln!("outputs {case}: {e}");
                    }
                }
            }
            Err(e) => {
                errors += 1;
                eprintln!("replay {case}: {e}");
            }
        }
    }
    eprintln!("{reports} reports, {errors} errors");
    assert!(reports > 0, "no log went through");
    let _ = std::fs::remove_dir_all(&out);
}

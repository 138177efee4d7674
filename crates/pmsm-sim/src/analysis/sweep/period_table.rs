//! `pmsm-sim run --csv` / `--parquet`: the run's per-period table, a row per PWM period, for
//! pandas, polars or a spreadsheet (`<out>/periods.csv`, `<out>/periods.parquet`). It shares
//! the sweep's typed columns and Parquet writer ([`super::table`], [`super::parquet_out`]).
//!
//! Columns (SI units, electrical angles and speeds unless named `_rpm`; vectors split into
//! named fields): `k`, `t_s`; the truth: `theta_e_rad`, `omega_e_rad_s`, `speed_rpm`,
//! `i_alpha_a`, `i_beta_a`, `i_d_a`, `i_q_a`, `torque_nm`, `load_torque_nm`, `psi_f_wb`,
//! `rs_ohm`; measured `i_alpha_meas_a`, `i_beta_meas_a`, `u_dc_meas_v`; the default EKF
//! (`ekf_`: `theta_e_rad`, `omega_e_rad_s`, `angle_error_deg`, `nis`, `tracking`, `psi_f_wb`,
//! `rs_ohm`); the controller's own observer (`foc_`: the same, null without one); the control
//! (`speed_ref_rpm`, `state`, `closed_loop`, `fault`, `i_d_ref_a`, `i_q_ref_a`); the inverter
//! (`pwm_enabled`, `duty_a`, `duty_b`, `duty_c`, `u_alpha_v`, `u_beta_v`, `u_dc_v`). The CSV
//! streams to disk; the Parquet table is held in memory until the end (about 40 numbers a
//! period, 16 bytes each).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::SimError;
use crate::output::SampleSink;
use crate::output::record::{ObserverSample, Sample};

use super::table::{Cell, Column, ColumnKind};

type Extract = fn(&Sample) -> Cell;

fn f(x: f64) -> Cell {
    if x.is_finite() {
        Cell::Float(x)
    } else {
        Cell::Null
    }
}

fn foc(s: &Sample, g: fn(&ObserverSample) -> Cell) -> Cell {
    s.controller_observer.as_ref().map_or(Cell::Null, g)
}

/// The columns: name and how a sample gives its value.
fn columns() -> Vec<(&'static str, ColumnKind, Extract)> {
    vec![
        ("k", ColumnKind::Int, |s| Cell::Int(s.k as i64)),
        ("t_s", ColumnKind::Float, |s| f(s.t_s)),
        ("theta_e_rad", ColumnKind::Float, |s| f(s.truth.theta_e_rad)),
        ("omega_e_rad_s", ColumnKind::Float, |s| {
            f(s.truth.omega_e_rad_s)
        }),
        ("speed_rpm", ColumnKind::Float, |s| f(s.truth.speed_rpm)),
        ("i_alpha_a", ColumnKind::Float, |s| f(s.truth.i_ab_a[0])),
        ("i_beta_a", ColumnKind::Float, |s| f(s.truth.i_ab_a[1])),
        ("i_d_a", ColumnKind::Float, |s| f(s.truth.i_dq_a[0])),
        ("i_q_a", ColumnKind::Float, |s| f(s.truth.i_dq_a[1])),
        ("torque_nm", ColumnKind::Float, |s| f(s.truth.torque_nm)),
        ("load_torque_nm", ColumnKind::Float, |s| {
            f(s.truth.load_torque_nm)
        }),
        ("psi_f_wb", ColumnKind::Float, |s| f(s.truth.psi_f_wb)),
        ("rs_ohm", ColumnKind::Float, |s| f(s.truth.rs_ohm)),
        ("i_alpha_meas_a", ColumnKind::Float, |s| {
            f(s.measured.i_ab_a[0])
        }),
        ("i_beta_meas_a", ColumnKind::Float, |s| {
            f(s.measured.i_ab_a[1])
        }),
        ("u_dc_meas_v", ColumnKind::Float, |s| f(s.measured.u_dc_v)),
        ("ekf_theta_e_rad", ColumnKind::Float, |s| {
            f(s.observer.theta_e_rad)
        }),
        ("ekf_omega_e_rad_s", ColumnKind::Float, |s| {
            f(s.observer.omega_e_rad_s)
        }),
        ("ekf_angle_error_deg", ColumnKind::Float, |s| {
            f(s.observer.angle_error_deg)
        }),
        ("ekf_nis", ColumnKind::Float, |s| f(s.observer.nis)),
        ("ekf_tracking", ColumnKind::Bool, |s| {
            Cell::Bool(s.observer.tracking)
        }),
        ("ekf_psi_f_wb", ColumnKind::Float, |s| {
            f(s.observer.psi_f_wb)
        }),
        ("ekf_rs_ohm", ColumnKind::Float, |s| f(s.observer.rs_ohm)),
        ("foc_theta_e_rad", ColumnKind::Float, |s| {
            foc(s, |o| f(o.theta_e_rad))
        }),
        ("foc_omega_e_rad_s", ColumnKind::Float, |s| {
            foc(s, |o| f(o.omega_e_rad_s))
        }),
        ("foc_angle_error_deg", ColumnKind::Float, |s| {
            foc(s, |o| f(o.angle_error_deg))
        }),
        ("foc_nis", ColumnKind::Float, |s| foc(s, |o| f(o.nis))),
        ("foc_tracking", ColumnKind::Bool, |s| {
            foc(s, |o| Cell::Bool(o.tracking))
        }),
        ("foc_psi_f_wb", ColumnKind::Float, |s| {
            foc(s, |o| f(o.psi_f_wb))
        }),
        ("foc_rs_ohm", ColumnKind::Float, |s| foc(s, |o| f(o.rs_ohm))),
        ("speed_ref_rpm", ColumnKind::Float, |s| {
            f(s.control.speed_ref_rpm)
        }),
        ("state", ColumnKind::Text, |s| {
            Cell::Text(s.control.telemetry.state.to_string())
        }),
        ("closed_loop", ColumnKind::Bool, |s| {
            Cell::Bool(s.control.telemetry.closed_loop)
        }),
        ("fault", ColumnKind::Text, |s| {
            s.control
                .telemetry
                .fault
                .map_or(Cell::Null, |x| Cell::Text(x.to_string()))
        }),
        ("i_d_ref_a", ColumnKind::Float, |s| {
            f(s.control.telemetry.i_dq_ref_a[0])
        }),
        ("i_q_ref_a", ColumnKind::Float, |s| {
            f(s.control.telemetry.i_dq_ref_a[1])
        }),
        ("pwm_enabled", ColumnKind::Bool, |s| {
            Cell::Bool(s.inverter.pwm_enabled)
        }),
        ("duty_a", ColumnKind::Float, |s| f(s.inverter.duties[0])),
        ("duty_b", ColumnKind::Float, |s| f(s.inverter.duties[1])),
        ("duty_c", ColumnKind::Float, |s| f(s.inverter.duties[2])),
        ("u_alpha_v", ColumnKind::Float, |s| f(s.inverter.u_ab_v[0])),
        ("u_beta_v", ColumnKind::Float, |s| f(s.inverter.u_ab_v[1])),
        ("u_dc_v", ColumnKind::Float, |s| f(s.inverter.u_dc_v)),
    ]
}

/// A CSV field: empty for null, text quoted when it holds a comma, quote or line break.
fn csv_field(c: &Cell, out: &mut String) {
    match c {
        Cell::Null => {}
        Cell::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        Cell::Int(i) => out.push_str(&i.to_string()),
        Cell::Float(x) => out.push_str(&x.to_string()),
        Cell::Text(s) if s.contains([',', '"', '\n']) => {
            out.push('"');
            out.push_str(&s.replace('"', "\"\""));
            out.push('"');
        }
        Cell::Text(s) => out.push_str(s),
    }
}

/// Appends a cell to its column (the cells of a column are of its kind, or null).
fn push(col: &mut Column, c: Cell) {
    match col {
        Column::Int(v) => v.push(match c {
            Cell::Int(i) => Some(i),
            _ => None,
        }),
        Column::Float(v) => v.push(match c {
            Cell::Float(x) => Some(x),
            _ => None,
        }),
        Column::Bool(v) => v.push(match c {
            Cell::Bool(b) => Some(b),
            _ => None,
        }),
        Column::Text(v) => v.push(match c {
            Cell::Text(t) => Some(t),
            _ => None,
        }),
    }
}

/// Where the rows go.
enum Target {
    Csv(std::io::BufWriter<std::fs::File>),
    Parquet(Vec<Column>),
}

/// A sink writing the per-period table ([`SampleSink`]); [`PeriodTable::finish`] completes
/// the file.
pub struct PeriodTable {
    path: PathBuf,
    columns: Vec<(&'static str, ColumnKind, Extract)>,
    target: Target,
    line: String,
}

impl PeriodTable {
    /// `<dir>/periods.csv` (`parquet` false) or `<dir>/periods.parquet`.
    pub fn create(dir: &Path, parquet: bool) -> Result<Self, SimError> {
        let columns = columns();
        let (path, target) = if parquet {
            let cols = columns
                .iter()
                .map(|(_, kind, _)| match kind {
                    ColumnKind::Int => Column::Int(Vec::new()),
                    ColumnKind::Float => Column::Float(Vec::new()),
                    ColumnKind::Bool => Column::Bool(Vec::new()),
                    ColumnKind::Text => Column::Text(Vec::new()),
                })
                .collect();
            (dir.join("periods.parquet"), Target::Parquet(cols))
        } else {
            let path = dir.join("periods.csv");
            let file = std::fs::File::create(&path).map_err(|e| SimError::Output {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
            let mut w = std::io::BufWriter::new(file);
            let header: Vec<&str> = columns.iter().map(|(n, _, _)| *n).collect();
            writeln!(w, "{}", header.join(",")).map_err(|e| SimError::Output {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
            (path, Target::Csv(w))
        };
        Ok(Self {
            path,
            columns,
            target,
            line: String::new(),
        })
    }

    /// Finishes the file and returns its path.
    pub fn finish(self) -> Result<PathBuf, SimError> {
        let err = |message: String| SimError::Output {
            path: self.path.display().to_string(),
            message,
        };
        match self.target {
            Target::Csv(mut w) => w.flush().map_err(|e| err(e.to_string()))?,
            Target::Parquet(cols) => {
                let named: Vec<(String, Column)> = self
                    .columns
                    .iter()
                    .zip(cols)
                    .map(|((name, _, _), c)| (name.to_string(), c))
                    .collect();
                super::parquet_out::write(&self.path, &named).map_err(err)?;
            }
        }
        Ok(self.path)
    }
}

impl SampleSink for PeriodTable {
    fn record(&mut self, sample: &Sample) -> Result<(), String> {
        match &mut self.target {
            Target::Csv(w) => {
                self.line.clear();
                for (k, (_, _, get)) in self.columns.iter().enumerate() {
                    if k > 0 {
                        self.line.push(',');
                    }
                    csv_field(&get(sample), &mut self.line);
                }
                self.line.push('\n');
                w.write_all(self.line.as_bytes())
                    .map_err(|e| format!("{}: {e}", self.path.display()))
            }
            Target::Parquet(cols) => {
                for ((_, _, get), col) in self.columns.iter().zip(cols.iter_mut()) {
                    push(col, get(sample));
                }
                Ok(())
            }
        }
    }
}

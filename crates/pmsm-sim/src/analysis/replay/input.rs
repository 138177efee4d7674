//! Reading a recorded drive: the CSV format and a `pmsm-sim` MCAP log into a [`DriveLog`], and the motor file into a [`ReplayMotor`] (the module docs give the formats).

use super::*;

/// Clarke scaling of a CSV log (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scaling {
    /// Amplitude-invariant (the project's).
    #[default]
    Amplitude,
    /// Power-invariant: values `sqrt(3/2)` times the amplitude-invariant ones.
    Power,
}

impl Scaling {
    /// By name: `amplitude` or `power`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "amplitude" => Some(Self::Amplitude),
            "power" => Some(Self::Power),
            _ => None,
        }
    }

    /// What a logged voltage or current is multiplied by to be amplitude-invariant.
    pub fn factor(self) -> f64 {
        match self {
            Self::Amplitude => 1.0,
            Self::Power => (2.0f64 / 3.0).sqrt(),
        }
    }
}

/// A drive log in the project's convention (module docs, "Alignment").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DriveLog {
    /// Time of each current sample, s.
    pub t_s: Vec<f64>,
    /// The period that ended at row `k`, s.
    pub dt_s: Vec<f64>,
    /// Voltage held over `[t_k, t_k+1)`, V (amplitude-invariant).
    pub u_ab: Vec<[f64; 2]>,
    /// Currents sampled at `t_k`, A (amplitude-invariant).
    pub i_ab: Vec<[f64; 2]>,
    /// Voltage over the period that ended at row 0, V.
    pub u_prev: [f64; 2],
    /// Reference electrical angle, rad (scoring only).
    pub theta_ref: Option<Vec<f64>>,
    /// Reference electrical speed, rad/s (scoring only).
    pub omega_ref: Option<Vec<f64>>,
}

#[cfg(test)]
impl DriveLog {
    /// A log of `theta_ref.len()` rows at the period `ts` with the reference angle and speed
    /// given and no voltage or current (for the tests of the scoring's diagnostics).
    pub(crate) fn reference_only(ts: f64, theta_ref: Vec<f64>, omega_ref: Vec<f64>) -> Self {
        let n = theta_ref.len();
        Self {
            t_s: (0..n).map(|k| k as f64 * ts).collect(),
            dt_s: vec![ts; n],
            u_ab: vec![[0.0; 2]; n],
            i_ab: vec![[0.0; 2]; n],
            u_prev: [0.0; 2],
            theta_ref: Some(theta_ref),
            omega_ref: Some(omega_ref),
        }
    }
}

impl DriveLog {
    /// Rows.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// No rows.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Checks that every array has the rows of `t_s` and that the periods are finite and
    /// positive (what the readers guarantee; for a log built by hand).
    pub fn check(&self) -> Result<(), ReplayError> {
        let n = self.len();
        let lens = [
            ("dt_s", self.dt_s.len()),
            ("u_ab", self.u_ab.len()),
            ("i_ab", self.i_ab.len()),
            ("theta_ref", self.theta_ref.as_ref().map_or(n, Vec::len)),
            ("omega_ref", self.omega_ref.as_ref().map_or(n, Vec::len)),
        ];
        for (name, l) in lens {
            if l != n {
                return Err(ReplayError::Inconsistent(format!(
                    "{name} has {l} rows, t_s {n}"
                )));
            }
        }
        if let Some(k) = self.dt_s.iter().position(|d| !(d.is_finite() && *d > 0.0)) {
            return Err(ReplayError::Inconsistent(format!(
                "dt_s[{k}] = {} is not a positive period",
                self.dt_s[k]
            )));
        }
        Ok(())
    }
}

pub(super) const REQUIRED: [&str; 6] = [
    "t_s",
    "dt_s",
    "u_alpha_v",
    "u_beta_v",
    "i_alpha_a",
    "i_beta_a",
];
pub(super) const OPTIONAL: [&str; 2] = ["theta_ref_rad", "omega_ref_rad_s"];

/// Parses a CSV log (module docs) from `bytes`; `file` names it in errors.
pub fn parse_csv(bytes: &[u8], file: &str, scaling: Scaling) -> Result<DriveLog, ReplayError> {
    let err = |line: usize, column: usize, problem: String| ReplayError::Csv {
        file: file.to_string(),
        line,
        column,
        problem,
    };
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut lines = bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .map(|(n, l)| (n + 1, l.strip_suffix(b"\r").unwrap_or(l)));
    fn text(
        n: usize,
        l: &[u8],
        err: impl Fn(usize, usize, String) -> ReplayError,
    ) -> Result<&str, ReplayError> {
        std::str::from_utf8(l).map_err(|e| {
            let before = &l[..e.valid_up_to()];
            let column = before.iter().filter(|&&b| b == b',').count() + 1;
            err(n, column, "not UTF-8 text".into())
        })
    }
    // Header: the first line that is not blank.
    let (header_line, header) = loop {
        match lines.next() {
            None => return Err(err(1, 1, "empty file: no header row".into())),
            Some((n, l)) => {
                let s = text(n, l, err)?;
                if !s.trim().is_empty() {
                    break (n, s);
                }
            }
        }
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    for (c, name) in names.iter().enumerate() {
        if names[..c].contains(name) && !name.is_empty() {
            return Err(err(header_line, c + 1, format!("column `{name}` repeated")));
        }
    }
    let find = |name: &str| names.iter().position(|n| *n == name);
    let mut idx = [0usize; 6];
    for (slot, name) in idx.iter_mut().zip(REQUIRED) {
        *slot = find(name).ok_or_else(|| {
            err(
                header_line,
                names.len() + 1,
                format!(
                    "missing column `{name}` (required: {}; the header has: {})",
                    REQUIRED.join(", "),
                    names.join(", ")
                ),
            )
        })?;
    }
    let opt: [Option<usize>; 2] = [find(OPTIONAL[0]), find(OPTIONAL[1])];
    let k = scaling.factor();
    let mut t = Vec::new();
    let mut dt = Vec::new();
    let mut u = Vec::new();
    let mut i = Vec::new();
    let mut th: Option<Vec<f64>> = opt[0].map(|_| Vec::new());
    let mut om: Option<Vec<f64>> = opt[1].map(|_| Vec::new());
    let mut cells: Vec<&str> = Vec::with_capacity(names.len());
    for (n, l) in lines {
        let s = text(n, l, err)?;
        if s.trim().is_empty() {
            continue;
        }
        cells.clear();
        cells.extend(s.split(','));
        if cells.len() != names.len() {
            let column = cells.len().min(names.len()) + 1;
            return Err(err(
                n,
                column,
                format!("{} cells, the header has {}", cells.len(), names.len()),
            ));
        }
        let num = |c: usize| -> Result<f64, ReplayError> {
            let cell = cells[c].trim();
            let v: f64 = cell.parse().map_err(|_| {
                err(
                    n,
                    c + 1,
                    format!("`{}`: {cell:?} is not a number", names[c]),
                )
            })?;
            if !v.is_finite() {
                return Err(err(
                    n,
                    c + 1,
                    format!("`{}`: {cell} is not finite", names[c]),
                ));
            }
            Ok(v)
        };
        let row: [f64; 6] = [
            num(idx[0])?,
            num(idx[1])?,
            num(idx[2])?,
            num(idx[3])?,
            num(idx[4])?,
            num(idx[5])?,
        ];
        if row[1] <= 0.0 {
            return Err(err(
                n,
                idx[1] + 1,
                format!("`dt_s` must be > 0, is {}", row[1]),
            ));
        }
        if let (Some(c), Some(v)) = (opt[0], th.as_mut()) {
            v.push(num(c)?);
        }
        if let (Some(c), Some(v)) = (opt[1], om.as_mut()) {
            v.push(num(c)?);
        }
        t.push(row[0]);
        dt.push(row[1]);
        u.push([row[2] * k, row[3] * k]);
        i.push([row[4] * k, row[5] * k]);
    }
    if t.is_empty() {
        return Err(err(
            header_line + 1,
            1,
            "no data rows after the header".into(),
        ));
    }
    let u_prev = u[0];
    let mut u_ab: Vec<[f64; 2]> = u[1..].to_vec();
    u_ab.push(u[u.len() - 1]);
    Ok(DriveLog {
        t_s: t,
        dt_s: dt,
        u_ab,
        i_ab: i,
        u_prev,
        theta_ref: th,
        omega_ref: om,
    })
}

/// Reads a CSV log (module docs).
pub fn read_csv(path: &Path, scaling: Scaling) -> Result<DriveLog, ReplayError> {
    let bytes = std::fs::read(path).map_err(|source| ReplayError::Io {
        file: path.display().to_string(),
        source,
    })?;
    parse_csv(&bytes, &path.display().to_string(), scaling)
}

/// The MCAP magic bytes at the start of a file.
pub(super) const MCAP_MAGIC: &[u8] = crate::analysis::mcap_input::MCAP_MAGIC;

/// Reads a `pmsm-sim` MCAP log (module docs) through the tuner's reader
/// ([`LoggedRun::read`](crate::analysis::tune::LoggedRun::read), streamed and bounded: a
/// corrupt file is an error naming the file and what is wrong, never a panic).
pub fn read_mcap(path: &Path) -> Result<DriveLog, ReplayError> {
    let file = path.display().to_string();
    let run = crate::analysis::tune::LoggedRun::read(path).map_err(|e| ReplayError::Mcap {
        file: file.clone(),
        message: match e {
            crate::analysis::tune::TuneError::Log { message, .. } => message,
            e => e.to_string(),
        },
    })?;
    let n = run.u_ab.len();
    if n == 0 {
        return Err(ReplayError::Mcap {
            file,
            message: "no period messages".into(),
        });
    }
    let ts = run.scenario.ts_s();
    Ok(DriveLog {
        t_s: (0..n).map(|k| k as f64 * ts).collect(),
        dt_s: vec![ts; n],
        u_ab: run.u_ab,
        i_ab: run.i_ab,
        u_prev: [0.0; 2],
        theta_ref: Some(run.theta_true),
        omega_ref: Some(run.omega_true),
    })
}

/// Reads a log: MCAP when the file starts with the MCAP magic, else CSV (`scaling` applies
/// to CSV only: the simulator's logs are amplitude-invariant).
pub fn read_log(path: &Path, scaling: Scaling) -> Result<DriveLog, ReplayError> {
    let io = |source| ReplayError::Io {
        file: path.display().to_string(),
        source,
    };
    // The first bytes decide; an MCAP file is streamed, not read whole.
    let mut head = Vec::with_capacity(MCAP_MAGIC.len());
    std::fs::File::open(path)
        .and_then(|f| {
            std::io::Read::read_to_end(
                &mut std::io::Read::take(f, MCAP_MAGIC.len() as u64),
                &mut head,
            )
        })
        .map_err(io)?;
    if head == MCAP_MAGIC {
        read_mcap(path)
    } else {
        let bytes = std::fs::read(path).map_err(io)?;
        parse_csv(&bytes, &path.display().to_string(), scaling)
    }
}

/// The motor of a log and its nominal period (`RUN.toml`: `rs_ohm`, `ld_h` and `lq_h` or
/// `ls_h`, `psi_f_wb`, `pole_pairs`, `ts_s`; optional `voltage_delay_s`, the drive's delay of
/// the applied voltage behind the logged one, negative for a lead, within `[-2 ts_s, 2 ts_s]`,
/// default 0: [`ekf_core::ObserverConfig::voltage_delay_s`]; optional `inverter_voltage_v`,
/// the inverter's voltage error as self-commissioning reports it, within `[0, 100]` V, default
/// 0: [`ekf_core::ObserverConfig::inverter_voltage_v`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReplayMotor {
    /// Motor parameters.
    #[serde(skip)]
    pub params: MotorParams<f64>,
    /// Nominal control period, s.
    pub ts_s: f64,
    /// Delay of the applied voltage behind the logged one, s (negative: a lead).
    pub voltage_delay_s: f64,
    /// The inverter's voltage error, V.
    pub inverter_voltage_v: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MotorToml {
    pub(super) rs_ohm: f64,
    pub(super) ld_h: Option<f64>,
    pub(super) lq_h: Option<f64>,
    pub(super) ls_h: Option<f64>,
    pub(super) psi_f_wb: f64,
    pub(super) pole_pairs: u32,
    pub(super) ts_s: f64,
    pub(super) voltage_delay_s: Option<f64>,
    pub(super) inverter_voltage_v: Option<f64>,
}

/// Parses a motor TOML; `file` names it in errors.
pub fn parse_motor(text: &str, file: &str) -> Result<ReplayMotor, ReplayError> {
    let err = |problem: String| ReplayError::Motor {
        file: file.to_string(),
        problem,
    };
    let m: MotorToml = toml::from_str(text).map_err(|e| {
        let mut p = e.message().trim().to_string();
        if let Some(span) = e.span() {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            p = format!("{p} (line {line}, column {col})");
        }
        err(p)
    })?;
    let (ld, lq) = match (m.ls_h, m.ld_h, m.lq_h) {
        (Some(ls), None, None) => (ls, ls),
        (None, Some(ld), Some(lq)) => (ld, lq),
        _ => {
            return Err(err(
                "give either `ls_h` (surface motor) or both `ld_h` and `lq_h`".into(),
            ));
        }
    };
    for (name, v) in [
        ("rs_ohm", m.rs_ohm),
        ("ld_h", ld),
        ("lq_h", lq),
        ("psi_f_wb", m.psi_f_wb),
        ("ts_s", m.ts_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(err(format!("`{name}` must be finite and > 0, is {v}")));
        }
    }
    let params = MotorParams::salient_from_f64(m.rs_ohm, ld, lq, m.psi_f_wb, m.pole_pairs);
    params.validate().map_err(|e| err(e.to_string()))?;
    let voltage_delay_s = m.voltage_delay_s.unwrap_or(0.0);
    if !(voltage_delay_s.is_finite() && voltage_delay_s.abs() <= 2.0 * m.ts_s) {
        return Err(err(format!(
            "`voltage_delay_s` must be within [-2 ts_s, 2 ts_s] = [{}, {}] s, is {voltage_delay_s}",
            -2.0 * m.ts_s,
            2.0 * m.ts_s
        )));
    }
    let inverter_voltage_v = m.inverter_voltage_v.unwrap_or(0.0);
    if !(inverter_voltage_v.is_finite() && (0.0..=100.0).contains(&inverter_voltage_v)) {
        return Err(err(format!(
            "`inverter_voltage_v` must be within [0, 100] V, is {inverter_voltage_v}"
        )));
    }
    Ok(ReplayMotor {
        params,
        ts_s: m.ts_s,
        voltage_delay_s,
        inverter_voltage_v,
    })
}

/// Reads a motor TOML.
pub fn read_motor(path: &Path) -> Result<ReplayMotor, ReplayError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| ReplayError::Io {
        file: file.clone(),
        source,
    })?;
    parse_motor(&text, &file)
}

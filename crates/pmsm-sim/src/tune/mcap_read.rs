//! Reading a run back from a `pmsm-sim` MCAP log: the scenario (`/pmsm_sim/scenario`, JSON)
//! and, per period (`/pmsm_sim/period`, protobuf or JSON), the few fields the tuner needs.
//!
//! The file is streamed (`mcap`'s sans-io `LinearReader`), so its size is bounded by the
//! memory of the extracted columns (about 90 bytes per period), not by the file's.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader};

use super::TuneError;
use crate::mcap_log::{TOPIC_PERIOD, TOPIC_SCENARIO};
use crate::scenario::Scenario;

/// The per-period fields the tuner reads, in `pmsm_sim.Period` terms.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PeriodFields {
    pub k: u64,
    pub theta_true: f64,
    pub omega_true: f64,
    pub i_meas: [f64; 2],
    pub observer_theta: f64,
    pub observer_nis: f64,
    pub u_ab_ref: [f64; 2],
    pub pwm_enabled: bool,
    pub u_commanded: [f64; 2],
}

/// What the tuner takes from a log.
#[derive(Clone, Debug)]
pub(crate) struct RawLog {
    pub scenario: Scenario,
    pub periods: Vec<PeriodFields>,
}

fn err(path: &Path, message: impl Into<String>) -> TuneError {
    TuneError::Log {
        path: path.display().to_string(),
        message: message.into(),
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Encoding {
    Protobuf,
    Json,
}

/// Reads the scenario and the period fields of a log (periods sorted by `k`).
pub(crate) fn read_log(path: &Path) -> Result<RawLog, TuneError> {
    let mut file = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
    let mut reader = LinearReader::new();
    let mut channels: std::collections::HashMap<u16, (String, Encoding)> =
        std::collections::HashMap::new();
    let mut scenario: Option<Scenario> = None;
    let mut periods = Vec::new();
    while let Some(event) = reader.next_event() {
        let event = event.map_err(|e| err(path, format!("not a readable MCAP file: {e}")))?;
        match event {
            LinearReadEvent::ReadRequest(need) => {
                let n = file
                    .read(reader.insert(need))
                    .map_err(|e| err(path, format!("read error: {e}")))?;
                reader.notify_read(n);
            }
            LinearReadEvent::Record { opcode, data } => {
                let record = mcap::parse_record(opcode, data)
                    .map_err(|e| err(path, format!("bad MCAP record: {e}")))?;
                match record {
                    Record::Channel(c) => {
                        let enc = match c.message_encoding.as_str() {
                            "protobuf" => Encoding::Protobuf,
                            _ => Encoding::Json,
                        };
                        channels.insert(c.id, (c.topic.clone(), enc));
                    }
                    Record::Message { header, data } => {
                        let Some((topic, enc)) = channels.get(&header.channel_id) else {
                            continue;
                        };
                        if topic == TOPIC_PERIOD {
                            let p = match enc {
                                Encoding::Protobuf => decode_period(&data),
                                Encoding::Json => period_from_json(&data),
                            }
                            .map_err(|e| {
                                err(path, format!("period message {}: {e}", periods.len()))
                            })?;
                            periods.push(p);
                        } else if topic == TOPIC_SCENARIO && scenario.is_none() {
                            scenario = Some(
                                scenario_from_json(&data)
                                    .map_err(|e| err(path, format!("scenario message: {e}")))?,
                            );
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    let scenario = scenario.ok_or_else(|| {
        err(
            path,
            format!("no {TOPIC_SCENARIO} message (not a pmsm-sim log?)"),
        )
    })?;
    periods.sort_by_key(|p| p.k);
    for (i, p) in periods.iter().enumerate() {
        if p.k != i as u64 {
            return Err(err(
                path,
                format!(
                    "periods are not contiguous from 0: period {} at index {i}",
                    p.k
                ),
            ));
        }
    }
    Ok(RawLog { scenario, periods })
}

fn scenario_from_json(data: &[u8]) -> Result<Scenario, String> {
    let v: serde_json::Value = serde_json::from_slice(data).map_err(|e| e.to_string())?;
    let toml = v
        .get("toml")
        .and_then(|t| t.as_str())
        .ok_or("no \"toml\" field")?;
    Scenario::from_toml_str(toml, "the log's scenario").map_err(|e| e.to_string())
}

fn period_from_json(data: &[u8]) -> Result<PeriodFields, String> {
    let v: serde_json::Value = serde_json::from_slice(data).map_err(|e| e.to_string())?;
    let num = |ptr: &str| -> Result<f64, String> {
        v.pointer(ptr)
            .and_then(serde_json::Value::as_f64)
            .ok_or_else(|| format!("missing number {ptr}"))
    };
    let pair = |ptr: &str| -> Result<[f64; 2], String> {
        Ok([num(&format!("{ptr}/0"))?, num(&format!("{ptr}/1"))?])
    };
    Ok(PeriodFields {
        k: v.pointer("/k")
            .and_then(serde_json::Value::as_u64)
            .ok_or("missing k")?,
        theta_true: num("/truth/theta_e_rad")?,
        omega_true: num("/truth/omega_e_rad_s")?,
        i_meas: pair("/measured/i_ab_a")?,
        observer_theta: num("/observer/theta_e_rad")?,
        observer_nis: num("/observer/nis")?,
        u_ab_ref: pair("/control/telemetry/u_ab_ref_v")?,
        pwm_enabled: v
            .pointer("/inverter/pwm_enabled")
            .and_then(serde_json::Value::as_bool)
            .ok_or("missing inverter.pwm_enabled")?,
        u_commanded: pair("/inverter/u_ab_commanded_v")?,
    })
}

// ---------------------------------------------------------------------------------------------
// Protobuf: a reader of the wire format for the fields above (schema src/schemas/period.proto).

/// One field on the wire.
enum Wire<'a> {
    Varint(u64),
    I64([u8; 8]),
    Len(&'a [u8]),
    I32,
}

/// Iterates over `(field number, value)` of a message body.
struct Fields<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    fn new(b: &'a [u8]) -> Self {
        Self { b, pos: 0 }
    }

    fn varint(&mut self) -> Result<u64, String> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let byte = *self.b.get(self.pos).ok_or("truncated varint")?;
            self.pos += 1;
            v |= u64::from(byte & 0x7f) << shift;
            if byte < 0x80 {
                return Ok(v);
            }
        }
        Err("varint too long".into())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or("truncated field")?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn next_field(&mut self) -> Option<Result<(u32, Wire<'a>), String>> {
        if self.pos >= self.b.len() {
            return None;
        }
        Some((|| {
            let key = self.varint()?;
            let number = u32::try_from(key >> 3).map_err(|_| "field number too large")?;
            let w = match key & 7 {
                0 => Wire::Varint(self.varint()?),
                1 => {
                    let mut a = [0u8; 8];
                    a.copy_from_slice(self.take(8)?);
                    Wire::I64(a)
                }
                2 => {
                    let n = usize::try_from(self.varint()?).map_err(|_| "length too large")?;
                    Wire::Len(self.take(n)?)
                }
                5 => {
                    self.take(4)?;
                    Wire::I32
                }
                wt => return Err(format!("unsupported wire type {wt}")),
            };
            Ok((number, w))
        })())
    }
}

/// Visits every field of a message body.
fn each<'a>(
    b: &'a [u8],
    mut f: impl FnMut(u32, Wire<'a>) -> Result<(), String>,
) -> Result<(), String> {
    let mut it = Fields::new(b);
    while let Some(r) = it.next_field() {
        let (n, w) = r?;
        f(n, w)?;
    }
    Ok(())
}

fn double(w: &Wire<'_>, name: &str) -> Result<f64, String> {
    match w {
        Wire::I64(a) => Ok(f64::from_le_bytes(*a)),
        _ => Err(format!("{name}: expected a double")),
    }
}

/// A `repeated double` of two values (packed, or one value per field).
fn pair_into(w: &Wire<'_>, out: &mut Vec<f64>, name: &str) -> Result<(), String> {
    match w {
        Wire::Len(body) if body.len() % 8 == 0 => {
            out.extend(
                body.chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))),
            );
            Ok(())
        }
        Wire::I64(a) => {
            out.push(f64::from_le_bytes(*a));
            Ok(())
        }
        _ => Err(format!("{name}: expected repeated double")),
    }
}

fn two(v: &[f64], name: &str) -> Result<[f64; 2], String> {
    match v {
        [a, b] => Ok([*a, *b]),
        _ => Err(format!("{name}: expected 2 values, got {}", v.len())),
    }
}

fn sub<'a>(w: Wire<'a>, name: &str) -> Result<&'a [u8], String> {
    match w {
        Wire::Len(b) => Ok(b),
        _ => Err(format!("{name}: expected a message")),
    }
}

/// Decodes the fields the tuner needs from one `pmsm_sim.Period` message (field numbers of
/// `src/schemas/period.proto`); proto3 defaults where a field is absent.
pub(crate) fn decode_period(b: &[u8]) -> Result<PeriodFields, String> {
    let mut p = PeriodFields::default();
    let (mut i_meas, mut u_ref, mut u_cmd) = (Vec::new(), Vec::new(), Vec::new());
    each(b, |n, w| {
        match n {
            1 => match w {
                Wire::Varint(v) => p.k = v,
                _ => return Err("k: expected a varint".into()),
            },
            // Truth: theta_e_rad 1, omega_e_rad_s 2.
            3 => each(sub(w, "truth")?, |n, w| {
                match n {
                    1 => p.theta_true = double(&w, "truth.theta_e_rad")?,
                    2 => p.omega_true = double(&w, "truth.omega_e_rad_s")?,
                    _ => {}
                }
                Ok(())
            })?,
            // Measured: i_ab_a 2.
            4 => each(sub(w, "measured")?, |n, w| {
                if n == 2 {
                    pair_into(&w, &mut i_meas, "measured.i_ab_a")?;
                }
                Ok(())
            })?,
            // ObserverSample: theta_e_rad 1, nis 6.
            5 => each(sub(w, "observer")?, |n, w| {
                match n {
                    1 => p.observer_theta = double(&w, "observer.theta_e_rad")?,
                    6 => p.observer_nis = double(&w, "observer.nis")?,
                    _ => {}
                }
                Ok(())
            })?,
            // Control: telemetry 3 -> u_ab_ref_v 7.
            8 => each(sub(w, "control")?, |n, w| {
                if n == 3 {
                    each(sub(w, "control.telemetry")?, |n, w| {
                        if n == 7 {
                            pair_into(&w, &mut u_ref, "control.telemetry.u_ab_ref_v")?;
                        }
                        Ok(())
                    })?;
                }
                Ok(())
            })?,
            // Inverter: pwm_enabled 1, u_ab_commanded_v 4.
            9 => each(sub(w, "inverter")?, |n, w| {
                match (n, w) {
                    (1, Wire::Varint(v)) => p.pwm_enabled = v != 0,
                    (1, _) => return Err("inverter.pwm_enabled: expected a varint".into()),
                    (4, w) => pair_into(&w, &mut u_cmd, "inverter.u_ab_commanded_v")?,
                    _ => {}
                }
                Ok(())
            })?,
            _ => {}
        }
        Ok(())
    })?;
    p.i_meas = two(&i_meas, "measured.i_ab_a")?;
    // Absent repeated fields are empty: zero voltage (proto3 default of the encoder's zeros).
    p.u_ab_ref = if u_ref.is_empty() {
        [0.0; 2]
    } else {
        two(&u_ref, "control.telemetry.u_ab_ref_v")?
    };
    p.u_commanded = if u_cmd.is_empty() {
        [0.0; 2]
    } else {
        two(&u_cmd, "inverter.u_ab_commanded_v")?
    };
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap_log::proto::PeriodEncoder;
    use crate::sim::Sample;

    /// The decoder reads back what the encoder wrote, and agrees with the JSON encoding.
    #[test]
    fn decodes_the_encoders_messages() {
        let mut s = Sample {
            k: 77,
            ..Sample::default()
        };
        s.truth.theta_e_rad = 1.25;
        s.truth.omega_e_rad_s = -300.5;
        s.measured.i_ab_a = [0.125, -2.5];
        s.observer.theta_e_rad = 1.3;
        s.observer.nis = 2.75;
        s.control.telemetry.u_ab_ref_v = [10.5, -20.25];
        s.inverter.pwm_enabled = true;
        s.inverter.u_ab_commanded_v = [11.0, -21.0];
        let mut enc = PeriodEncoder::new();
        let p = decode_period(enc.encode(&s)).unwrap_or_else(|e| panic!("{e}"));
        let want = PeriodFields {
            k: 77,
            theta_true: 1.25,
            omega_true: -300.5,
            i_meas: [0.125, -2.5],
            observer_theta: 1.3,
            observer_nis: 2.75,
            u_ab_ref: [10.5, -20.25],
            pwm_enabled: true,
            u_commanded: [11.0, -21.0],
        };
        assert_eq!(p, want);
        let json = serde_json::to_vec(&s).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(period_from_json(&json), Ok(want));
        // Truncated messages are errors, not panics.
        let bytes = enc.encode(&s).to_vec();
        for cut in [1, 5, bytes.len() - 1] {
            assert!(decode_period(&bytes[..cut]).is_err(), "cut {cut}");
        }
        // Any cut: a result or an error, never a panic.
        for cut in 0..bytes.len() {
            let _ = decode_period(&bytes[..cut]);
        }
        assert!(period_from_json(b"{\"k\": 1}").is_err());
    }
}

//! Reading a run back from a `pmsm-sim` MCAP log: the scenario (`/pmsm_sim/scenario`, JSON)
//! and, per period (`/pmsm_sim/period`, protobuf or JSON), the few fields the tuner needs.
//! Protobuf messages go through the one decoder of the record,
//! [`decode_to_json`](crate::output::mcap::proto::decode_to_json), to the JSON value of the JSON
//! encoding; the fields are then read from that value the same way for both encodings.
//!
//! The file is streamed by the safe MCAP reader ([`read_records`]: a structure check, then
//! `mcap`'s sans-io `LinearReader` with bounded record lengths), so the memory is that of the
//! extracted columns (about 90 bytes per period), not the file's size; a corrupt file is a
//! [`TuneError::Log`] naming the file, never a panic.

use std::path::Path;

use mcap::records::Record;

use super::TuneError;
use crate::analysis::mcap_input::read_records;
use crate::output::mcap::proto::decode_to_json;
use crate::output::mcap::{TOPIC_PERIOD, TOPIC_SCENARIO};
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

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Protobuf,
    Json,
}

/// Reads the scenario and the period fields of a log (periods sorted by `k`); the records
/// come from [`read_records`] (a corrupt file is an error, never a panic).
pub(crate) fn read_log(path: &Path) -> Result<RawLog, TuneError> {
    let mut channels: std::collections::HashMap<u16, (String, Encoding)> =
        std::collections::HashMap::new();
    let mut scenario: Option<Scenario> = None;
    let mut periods = Vec::new();
    read_records(path, |opcode, data| {
        let record =
            mcap::parse_record(opcode, data).map_err(|e| format!("bad MCAP record: {e}"))?;
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
                    return Ok(());
                };
                if topic == TOPIC_PERIOD {
                    let p = decode_period(&data, *enc)
                        .map_err(|e| format!("period message {}: {e}", periods.len()))?;
                    periods.push(p);
                } else if topic == TOPIC_SCENARIO && scenario.is_none() {
                    scenario = Some(
                        scenario_from_json(&data).map_err(|e| format!("scenario message: {e}"))?,
                    );
                }
            }
            _ => {}
        }
        Ok(())
    })
    .map_err(|m| err(path, m))?;
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

/// The tuner's fields of one period, from the JSON value of the record (what
/// [`decode_to_json`] makes of a protobuf message, or the JSON encoding as written).
fn period_fields(v: &serde_json::Value) -> Result<PeriodFields, String> {
    let num = |ptr: &str| -> Result<f64, String> {
        v.pointer(ptr)
            .and_then(serde_json::Value::as_f64)
            .ok_or_else(|| format!("missing number {ptr}"))
    };
    let pair = |ptr: &str| -> Result<[f64; 2], String> {
        match v.pointer(ptr).and_then(serde_json::Value::as_array) {
            // An empty repeated field is absent on the wire: the encoder's zeros.
            Some(a) if a.is_empty() => Ok([0.0; 2]),
            Some(_) => Ok([num(&format!("{ptr}/0"))?, num(&format!("{ptr}/1"))?]),
            None => Err(format!("missing array {ptr}")),
        }
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

/// Decodes one `/pmsm_sim/period` message in either encoding.
fn decode_period(data: &[u8], encoding: Encoding) -> Result<PeriodFields, String> {
    let v = match encoding {
        Encoding::Protobuf => decode_to_json("Period", data)?,
        Encoding::Json => serde_json::from_slice(data).map_err(|e| e.to_string())?,
    };
    period_fields(&v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::mcap::proto::PeriodEncoder;
    use crate::output::record::Sample;

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
        let p = decode_period(enc.encode(&s), Encoding::Protobuf).unwrap_or_else(|e| panic!("{e}"));
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
        assert_eq!(decode_period(&json, Encoding::Json), Ok(want));
        // Truncated messages are errors, not panics.
        let bytes = enc.encode(&s).to_vec();
        for cut in [1, 5, bytes.len() - 1] {
            assert!(
                decode_period(&bytes[..cut], Encoding::Protobuf).is_err(),
                "cut {cut}"
            );
        }
        // Any cut: a result or an error, never a panic.
        for cut in 0..bytes.len() {
            let _ = decode_period(&bytes[..cut], Encoding::Protobuf);
        }
        assert!(decode_period(b"{\"k\": 1}", Encoding::Json).is_err());
    }
}

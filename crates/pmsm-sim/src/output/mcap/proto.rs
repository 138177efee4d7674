//! The per-period message (`pmsm_sim.Period`) on the wire: its protobuf encoding, and the
//! schema files made from the one description of the record in [`crate::output::record`].
//!
//! - [`PeriodEncoder`]: the protobuf encoding of a [`Sample`] (about 70 ns and 1000 bytes per
//!   message: straight-line code the `record!` macro generates, no allocation).
//! - [`file_descriptor_set`]: the `FileDescriptorSet` the log carries as the schema of
//!   encoding `protobuf` (what Foxglove and the `mcap` Python package with
//!   `mcap-protobuf-support` decode with); byte for byte what `protoc --descriptor_set_out`
//!   writes for [`proto_text`].
//! - [`proto_text`], [`json_schema`]: the `.proto` text and the JSON schema (the schema of the
//!   JSON encoding, [`super::LogEncoding::Json`]).
//! - [`decode_to_json`]: the one decoder, protobuf to the JSON value of the JSON encoding, used
//!   by the tuner ([`crate::analysis::tune`]), the tests and the tools.
//!
//! `src/schemas/period.proto`, `period.desc` and `period.schema.json` are these outputs,
//! checked in for readers and tools; unit tests fail when they are stale, and
//! `PMSM_SIM_BLESS=1 cargo test -p pmsm-sim --lib schema` rewrites them (how to add a field:
//! [`crate::output::record`]).
//!
//! Field names are those of the JSON encoding (the [`Sample`] serialized by serde), so the
//! Foxglove paths are the same in both (`/pmsm_sim/period.observer.angle_error_deg`,
//! `/pmsm_sim/period.truth.i_ab_a[0]`). Absent in the protobuf message where JSON has `null`:
//! `Option` messages (`seed_filter`, `controller_observer`, `control.telemetry.estimate`) and
//! `Option` scalars (proto3 `optional`: `control.telemetry.speed_ref_rpm`, `.fault`).

use crate::output::record::{
    Card, Enc, FieldDef, MESSAGES, MessageDef, Sample, Ty, WT_I64, WT_LEN, WT_VARINT, encode_into,
    encode_period, message_def,
};

/// Package of the messages.
pub const PACKAGE: &str = "pmsm_sim";
/// Fully qualified name of the per-period message (the MCAP schema name).
pub const PERIOD_MESSAGE: &str = "pmsm_sim.Period";
/// File name inside the descriptor set.
pub const FILE_NAME: &str = "pmsm_sim/period.proto";

/// Encodes the `pmsm_sim.Period` message of a sample into a reused buffer.
#[derive(Clone, Debug, Default)]
pub struct PeriodEncoder {
    buf: Vec<u8>,
}

impl PeriodEncoder {
    /// An encoder (its buffer grows on first use).
    pub fn new() -> Self {
        Self::default()
    }

    /// The encoding of `s`, valid until the next call.
    #[inline]
    pub fn encode(&mut self, s: &Sample) -> &[u8] {
        let n = encode_period(&mut self.buf, s);
        &self.buf[..n]
    }
}

/// Encodes a whole message into a new vector (`capacity`: an upper bound of its size).
fn encode_vec(capacity: usize, body: impl FnOnce(&mut Enc<'_>)) -> Vec<u8> {
    let mut buf = Vec::new();
    let n = encode_into(&mut buf, capacity, body);
    buf.truncate(n);
    buf
}

// ---------------------------------------------------------------------------------------------
// The schema as a FileDescriptorSet (google/protobuf/descriptor.proto), as .proto text and as
// a JSON schema.

/// The `FileDescriptorSet` of the schema (one file, `proto3`, package [`PACKAGE`]): the MCAP
/// schema data of encoding `protobuf`. Byte for byte what `protoc --descriptor_set_out`
/// writes for [`proto_text`] (checked in as `src/schemas/period.desc`, made with protoc 3.21).
pub fn file_descriptor_set() -> Vec<u8> {
    // Generous: the set is about 2 KB (a unit test keeps it under 16 KB).
    const CAP: usize = 64 << 10;
    // FileDescriptorSet: file 1.
    encode_vec(CAP, |e| {
        e.message::<1>(1, |e| {
            // FileDescriptorProto: name 1, package 2, message_type 4, syntax 12.
            e.string(1, FILE_NAME);
            e.string(2, PACKAGE);
            for m in MESSAGES {
                e.message::<1>(4, |e| descriptor_proto(e, m));
            }
            e.string(12, "proto3");
        });
    })
}

/// A `DescriptorProto`: name 1, field 2, oneof_decl 8.
fn descriptor_proto(e: &mut Enc<'_>, m: &MessageDef) {
    e.string(1, m.name);
    let mut oneofs = 0u64;
    for fd in m.fields {
        // FieldDescriptorProto: name 1, number 3, label 4, type 5, type_name 6,
        // oneof_index 9, json_name 10, proto3_optional 17.
        e.message::<1>(2, |e| {
            e.string(1, fd.name);
            e.uint64(3, u64::from(fd.number));
            e.uint64(
                4,
                if matches!(fd.card, Card::Repeated(_)) {
                    3
                } else {
                    1
                },
            );
            let ty = match fd.ty {
                Ty::Double => 1,
                Ty::Uint64 => 4,
                Ty::Bool => 8,
                Ty::String => 9,
                Ty::Message(_) => 11,
            };
            e.uint64(5, ty);
            if let Ty::Message(name) = fd.ty {
                e.string(6, &format!(".{PACKAGE}.{name}"));
            }
            if fd.card == Card::Optional {
                e.uint64(9, oneofs);
                oneofs += 1;
            }
            e.string(10, &json_name(fd.name));
            if fd.card == Card::Optional {
                e.bool(17, true);
            }
        });
    }
    // The synthetic oneofs of the proto3 `optional` fields (there is no real oneof).
    for fd in m.fields.iter().filter(|fd| fd.card == Card::Optional) {
        e.message::<1>(8, |e| e.string(1, &format!("_{}", fd.name)));
    }
}

/// protoc's `json_name`: lowerCamelCase of the field name.
fn json_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut upper = false;
    for c in name.chars() {
        if c == '_' {
            upper = true;
        } else if upper {
            out.extend(c.to_uppercase());
            upper = false;
        } else {
            out.push(c);
        }
    }
    out
}

/// The schema as `.proto` text (checked in as `src/schemas/period.proto`).
pub fn proto_text() -> String {
    let mut s = String::new();
    s.push_str("// The per-period message of pmsm-sim's MCAP log (topic /pmsm_sim/period).\n");
    s.push_str("// Generated from crates/pmsm-sim/src/record.rs (a unit test checks that this\n");
    s.push_str("// file matches it); the log carries it as a FileDescriptorSet.\n");
    s.push_str("syntax = \"proto3\";\n\n");
    s.push_str(&format!("package {PACKAGE};\n"));
    for m in MESSAGES {
        s.push_str(&format!("\n// {}\nmessage {} {{\n", m.doc_line(), m.name));
        for fd in m.fields {
            let ty = match fd.ty {
                Ty::Double => "double",
                Ty::Uint64 => "uint64",
                Ty::Bool => "bool",
                Ty::String => "string",
                Ty::Message(n) => n,
            };
            let label = match fd.card {
                Card::Single => "",
                Card::Optional => "optional ",
                Card::Repeated(_) => "repeated ",
            };
            s.push_str(&format!(
                "  {label}{ty} {} = {};  // {}\n",
                fd.name,
                fd.number,
                fd.doc_line()
            ));
        }
        s.push_str("}\n");
    }
    s
}

/// The JSON schema (draft 2020-12) of the JSON encoding of `/pmsm_sim/period` (checked in as
/// `src/schemas/period.schema.json`): the same fields, `null` where the protobuf message
/// leaves a field out.
pub fn json_schema() -> serde_json::Value {
    use serde_json::{Value, json};
    fn message(m: &MessageDef) -> Value {
        let props: serde_json::Map<String, Value> = m
            .fields
            .iter()
            .map(|fd| (fd.name.to_string(), field(fd)))
            .collect();
        let required: Vec<&str> = m.fields.iter().map(|fd| fd.name).collect();
        json!({
            "type": "object",
            "description": m.doc_line(),
            "properties": props,
            "required": required,
            "additionalProperties": false,
        })
    }
    fn field(fd: &FieldDef) -> Value {
        let scalar = match fd.ty {
            Ty::Double => json!({"type": "number"}),
            Ty::Uint64 => json!({"type": "integer", "minimum": 0}),
            Ty::Bool => json!({"type": "boolean"}),
            Ty::String => json!({"type": "string"}),
            Ty::Message(name) => match message_def(name) {
                Some(m) => message(m),
                None => json!({}),
            },
        };
        let mut v = match (fd.card, fd.ty) {
            (Card::Repeated(n), _) => {
                json!({"type": "array", "items": scalar, "minItems": n, "maxItems": n})
            }
            _ if fd.nullable => {
                json!({"anyOf": [scalar, {"type": "null"}]})
            }
            _ => scalar,
        };
        if let Some(o) = v.as_object_mut() {
            o.insert("description".into(), Value::from(fd.doc_line()));
        }
        v
    }
    let mut top = match MESSAGES.first() {
        Some(m) => message(m),
        None => json!({}),
    };
    if let Some(o) = top.as_object_mut() {
        o.insert(
            "$schema".into(),
            "https://json-schema.org/draft/2020-12/schema".into(),
        );
        o.insert("title".into(), PERIOD_MESSAGE.into());
    }
    top
}

// ---------------------------------------------------------------------------------------------
// Decoding.

fn read_varint(b: &[u8], pos: &mut usize) -> Result<u64, String> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *b.get(*pos).ok_or("truncated varint")?;
        *pos += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte < 0x80 {
            return Ok(v);
        }
    }
    Err("varint too long".into())
}

fn take<'a>(b: &'a [u8], pos: &mut usize, n: usize) -> Result<&'a [u8], String> {
    let end = pos.checked_add(n).filter(|&e| e <= b.len());
    let end = end.ok_or("truncated field")?;
    let s = &b[*pos..end];
    *pos = end;
    Ok(s)
}

fn f64_at(b: &[u8]) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    f64::from_le_bytes(a)
}

fn read_len(b: &[u8], pos: &mut usize) -> Result<usize, String> {
    usize::try_from(read_varint(b, pos)?).map_err(|_| "length too large".to_string())
}

/// Decodes a message of the schema (short name, e.g. `"Period"`) into the JSON value of the
/// JSON encoding: absent messages and `optional` fields are `null`, absent scalars their
/// proto3 default (so a log written before a field was added reads with that default).
/// Unknown fields are skipped; a truncated or malformed message is an error, never a panic.
pub fn decode_to_json(message: &str, bytes: &[u8]) -> Result<serde_json::Value, String> {
    use serde_json::{Map, Value};
    let def = message_def(message).ok_or_else(|| format!("no message {message}"))?;
    let mut out = Map::new();
    for fd in def.fields {
        let v = match (fd.card, fd.ty) {
            (Card::Repeated(_), _) => Value::Array(Vec::new()),
            (Card::Optional, _) | (_, Ty::Message(_)) => Value::Null,
            (_, Ty::Double) => Value::from(0.0),
            (_, Ty::Uint64) => Value::from(0u64),
            (_, Ty::Bool) => Value::Bool(false),
            (_, Ty::String) => Value::from(""),
        };
        out.insert(fd.name.to_string(), v);
    }
    let mut pos = 0;
    while pos < bytes.len() {
        let k = read_varint(bytes, &mut pos)?;
        let (number, wt) = ((k >> 3) as u32, (k & 7) as u32);
        let Some(fd) = def.fields.iter().find(|fd| fd.number == number) else {
            match wt {
                WT_VARINT => {
                    read_varint(bytes, &mut pos)?;
                }
                WT_I64 => {
                    take(bytes, &mut pos, 8)?;
                }
                WT_LEN => {
                    let n = read_len(bytes, &mut pos)?;
                    take(bytes, &mut pos, n)?;
                }
                5 => {
                    take(bytes, &mut pos, 4)?;
                }
                _ => return Err(format!("{message}: wire type {wt}")),
            }
            continue;
        };
        let name = fd.name;
        let repeated = matches!(fd.card, Card::Repeated(_));
        let value = match (fd.ty, wt) {
            (Ty::Double, WT_I64) => Value::from(f64_at(take(bytes, &mut pos, 8)?)),
            (Ty::Double, WT_LEN) if repeated => {
                let n = read_len(bytes, &mut pos)?;
                let body = take(bytes, &mut pos, n)?;
                if !n.is_multiple_of(8) {
                    return Err(format!("{message}.{name}: packed length {n}"));
                }
                let vals = body.chunks(8).map(|c| Value::from(f64_at(c)));
                if let Some(Value::Array(a)) = out.get_mut(name) {
                    a.extend(vals);
                }
                continue;
            }
            (Ty::Uint64, WT_VARINT) => Value::from(read_varint(bytes, &mut pos)?),
            (Ty::Bool, WT_VARINT) => Value::Bool(read_varint(bytes, &mut pos)? != 0),
            (Ty::String, WT_LEN) => {
                let n = read_len(bytes, &mut pos)?;
                let s = std::str::from_utf8(take(bytes, &mut pos, n)?)
                    .map_err(|e| format!("{message}.{name}: {e}"))?;
                Value::from(s)
            }
            (Ty::Message(m), WT_LEN) => {
                let n = read_len(bytes, &mut pos)?;
                decode_to_json(m, take(bytes, &mut pos, n)?)?
            }
            _ => return Err(format!("{message}.{name}: unexpected wire type {wt}")),
        };
        if repeated {
            if let Some(Value::Array(a)) = out.get_mut(name) {
                a.push(value);
            }
        } else {
            out.insert(name.to_string(), value);
        }
    }
    Ok(Value::Object(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::record::{ControllerEstimate, ObserverSample, PERIOD_MAX_FIXED};

    /// `s` with every optional part absent (`None`).
    fn bare(mut s: Sample) -> Sample {
        s.seed_filter = None;
        s.controller_observer = None;
        s.control.telemetry.speed_ref_rpm = None;
        s.control.telemetry.fault = None;
        s.control.telemetry.estimate = None;
        s
    }

    /// A sample with every optional part present and distinct values everywhere.
    fn full_sample() -> Sample {
        let mut s = Sample::default();
        let mut x = 0.0;
        let mut next = || {
            x += 1.25;
            x
        };
        s.k = 123_456;
        s.t_s = 12.3456;
        s.truth.theta_e_rad = next();
        s.truth.omega_e_rad_s = -next();
        s.truth.speed_rpm = next();
        s.truth.i_ab_a = [next(), next()];
        s.truth.i_dq_a = [next(), -next()];
        s.truth.torque_nm = next();
        s.truth.load_torque_nm = next();
        s.truth.psi_f_wb = 0.171;
        s.truth.rs_ohm = 3.07;
        s.measured.i_abc_a = [next(), next(), next()];
        s.measured.i_ab_a = [next(), next()];
        s.measured.u_dc_v = 300.0;
        let mut obs = || ObserverSample {
            theta_e_rad: next(),
            omega_e_rad_s: next(),
            angle_error_deg: -next(),
            speed_error_rad_s: next(),
            p_diag: [next(), next(), next(), 1e-300],
            nis: next(),
            tracking: true,
            // Constants, not `next()`: the older fields keep the values of the 0.1.0
            // fixtures (`logs_written_before_still_decode`).
            psi_f_wb: 0.172,
            psi_f_sigma_wb: 2e-4,
            rs_ohm: 3.05,
            rs_sigma_ohm: 0.04,
            winding_temperature_c: 35.5,
        };
        s.observer = obs();
        s.seed_filter = Some(obs());
        s.controller_observer = Some(obs());
        s.control.speed_ref_rpm = 2000.0;
        s.control.duties = [0.1, 0.5, 0.9];
        let t = &mut s.control.telemetry;
        t.state = "closed_loop";
        t.theta_e_rad = 0.5;
        t.omega_e_rad_s = 800.0;
        t.i_dq_a = [0.01, 1.5];
        t.i_dq_ref_a = [0.0, 1.6];
        t.u_dq_ref_v = [-3.0, 40.0];
        t.u_ab_ref_v = [20.0, -30.0];
        t.voltage_limited = true;
        t.closed_loop = true;
        t.speed_ref_rpm = Some(1999.5);
        t.fault = Some("observer_lost");
        t.estimate = Some(ControllerEstimate {
            theta_e_rad: 0.25,
            omega_e_rad_s: 801.0,
            p_diag: [1e-3, 2e-3, 3.0, 4e-4],
            nis: 2.5,
            tracking: true,
            psi_f_wb: 0.17,
            psi_f_sigma_wb: 1e-4,
            rs_ohm: 3.1,
            rs_sigma_ohm: 0.05,
            winding_temperature_c: 41.5,
        });
        s.inverter.pwm_enabled = true;
        s.inverter.duties = [0.2, 0.4, 0.6];
        s.inverter.u_ab_v = [21.0, -31.0];
        s.inverter.u_ab_commanded_v = [22.0, -32.0];
        s.inverter.u_dc_v = 301.0;
        s
    }

    /// The protobuf message decodes (with the table) to exactly the JSON encoding of the
    /// sample: same names, same structure, same numbers; absent parts are `null` in both.
    #[test]
    fn protobuf_decodes_to_the_json_encoding() {
        let full = full_sample();
        let mut bare = bare(full);
        bare.control.telemetry.state = "";
        let mut enc = PeriodEncoder::new();
        for s in [full, bare, Sample::default()] {
            let decoded =
                decode_to_json("Period", enc.encode(&s)).unwrap_or_else(|e| panic!("{e}"));
            let json = serde_json::to_value(s).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(decoded, json);
        }
    }

    #[test]
    fn nested_lengths_of_any_size() {
        let buf = encode_vec(1 << 16, |e| {
            e.message::<1>(3, |e| {
                for i in 0..40 {
                    e.double(1, f64::from(i));
                }
            })
        });
        // key, length 360 = 0xe8 0x02, 40 x 9 bytes.
        assert_eq!(&buf[..3], &[0x1a, 0xe8, 0x02]);
        assert_eq!(buf.len(), 3 + 360);
        // The body follows: the doubles' keys (field 1, I64) every 9 bytes.
        assert_eq!((buf[3], buf[12], buf[354]), (0x09, 0x09, 0x09));
        // A short body in a two-byte reservation moves up by one.
        let buf = encode_vec(64, |e| e.message::<2>(3, |e| e.bool(2, true)));
        assert_eq!(buf, [0x1a, 2, 0x10, 1]);
        // A body of 2^14 bytes or more needs three.
        let buf = encode_vec(1 << 16, |e| e.message::<2>(3, |e| e.bytes(&[7; 20_000])));
        assert_eq!(&buf[..5], &[0x1a, 0xa0, 0x9c, 0x01, 7]);
        assert_eq!(buf.len(), 4 + 20_000);
    }

    /// The default's message is about 1 KB (what the log size per period is made of),
    /// well within the buffer reserved for it.
    #[test]
    fn message_size() {
        let mut s = full_sample();
        let mut enc = PeriodEncoder::new();
        let n = enc.encode(&s).len();
        assert!((900..1100).contains(&n), "{n}");
        s.control.telemetry.state = "";
        s.control.telemetry.fault = None;
        s.k = u64::MAX;
        assert!(enc.encode(&s).len() <= PERIOD_MAX_FIXED);
        // Long names grow the buffer.
        let long: &'static str = "x".repeat(5000).leak();
        s.control.telemetry.state = long;
        s.control.telemetry.fault = Some(long);
        let decoded = decode_to_json("Period", enc.encode(&s)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(decoded["control"]["telemetry"]["fault"], long);
        assert!(file_descriptor_set().len() < 16 << 10);
    }

    /// Logs written by pmsm-sim 0.1.0 (`tests/data/period-*-0.1.0.pb`, without the tracked
    /// parameters) read back: they decode to the JSON
    /// encoding of the same sample with the fields added since (the truth's and the
    /// observers' `psi_f`, `Rs`, deviations, temperature) at their proto3 default, 0.
    #[test]
    fn logs_written_before_still_decode() {
        let old_full: &[u8] = include_bytes!("../../../tests/data/period-full-0.1.0.pb");
        let old_bare: &[u8] = include_bytes!("../../../tests/data/period-bare-0.1.0.pb");
        let legacy = |mut s: Sample| {
            s.truth.psi_f_wb = 0.0;
            s.truth.rs_ohm = 0.0;
            let clear = |o: &mut ObserverSample| {
                o.psi_f_wb = 0.0;
                o.psi_f_sigma_wb = 0.0;
                o.rs_ohm = 0.0;
                o.rs_sigma_ohm = 0.0;
                o.winding_temperature_c = 0.0;
            };
            clear(&mut s.observer);
            if let Some(o) = &mut s.seed_filter {
                clear(o);
            }
            if let Some(o) = &mut s.controller_observer {
                clear(o);
            }
            if let Some(e) = &mut s.control.telemetry.estimate {
                e.psi_f_wb = 0.0;
                e.psi_f_sigma_wb = 0.0;
                e.rs_ohm = 0.0;
                e.rs_sigma_ohm = 0.0;
                e.winding_temperature_c = 0.0;
            }
            s
        };
        let full = full_sample();
        let bare = bare(full);
        for (s, old) in [(full, old_full), (bare, old_bare)] {
            let decoded = decode_to_json("Period", old).unwrap_or_else(|e| panic!("{e}"));
            let mut json = serde_json::to_value(legacy(s)).unwrap_or_else(|e| panic!("{e}"));
            // The named components came later too: absent, they read as 0.
            for (path, _, _) in NAMED {
                if let Some(v) = json.pointer_mut(path) {
                    *v = 0.0.into();
                }
            }
            assert_eq!(decoded, json);
        }
    }

    /// The named components of the vectors (JSON pointer, the array's pointer, index).
    const NAMED: [(&str, &str, usize); 12] = [
        ("/truth/i_alpha_a", "/truth/i_ab_a", 0),
        ("/truth/i_beta_a", "/truth/i_ab_a", 1),
        ("/truth/i_d_a", "/truth/i_dq_a", 0),
        ("/truth/i_q_a", "/truth/i_dq_a", 1),
        ("/control/telemetry/i_d_a", "/control/telemetry/i_dq_a", 0),
        ("/control/telemetry/i_q_a", "/control/telemetry/i_dq_a", 1),
        (
            "/control/telemetry/i_d_ref_a",
            "/control/telemetry/i_dq_ref_a",
            0,
        ),
        (
            "/control/telemetry/i_q_ref_a",
            "/control/telemetry/i_dq_ref_a",
            1,
        ),
        (
            "/control/telemetry/u_d_ref_v",
            "/control/telemetry/u_dq_ref_v",
            0,
        ),
        (
            "/control/telemetry/u_q_ref_v",
            "/control/telemetry/u_dq_ref_v",
            1,
        ),
        ("/inverter/u_alpha_v", "/inverter/u_ab_v", 0),
        ("/inverter/u_beta_v", "/inverter/u_ab_v", 1),
    ];

    /// Every named component decodes to its array's component, in the protobuf message and
    /// the JSON encoding alike (distinct values everywhere, so a swapped index fails).
    #[test]
    fn named_components_equal_the_arrays() {
        let s = full_sample();
        let mut enc = PeriodEncoder::new();
        let decoded = decode_to_json("Period", enc.encode(&s)).unwrap_or_else(|e| panic!("{e}"));
        let json = serde_json::to_value(s).unwrap_or_else(|e| panic!("{e}"));
        for doc in [&decoded, &json] {
            for (named, array, i) in NAMED {
                let v = doc.pointer(named).and_then(serde_json::Value::as_f64);
                let a = doc.pointer(array).and_then(|a| a[i].as_f64());
                assert!(
                    v.is_some() && v == a,
                    "{named}: {v:?} vs {array}[{i}]: {a:?}"
                );
            }
        }
        let t = &decoded["control"]["telemetry"];
        assert_eq!(
            t["u_q_ref_v"].as_f64(),
            Some(s.control.telemetry.u_dq_ref_v[1])
        );
        assert_eq!(decoded["truth"]["i_q_a"].as_f64(), Some(s.truth.i_dq_a[1]));
        // The table holds all of them (plus the arrays), once each.
        let named = MESSAGES
            .iter()
            .flat_map(|m| m.fields)
            .filter(|f| f.doc[0].contains("]` again"));
        assert_eq!(named.count(), NAMED.len());
    }

    /// Compares a checked-in schema file with what the table generates; with
    /// `PMSM_SIM_BLESS=1` in the environment, rewrites it instead.
    fn check_file(name: &str, generated: &[u8]) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("src/schemas")
            .join(name);
        if std::env::var_os("PMSM_SIM_BLESS").is_some() {
            std::fs::write(&path, generated).unwrap_or_else(|e| panic!("{e}"));
            return;
        }
        let file = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(
            file == generated,
            "src/schemas/{name} is stale: run PMSM_SIM_BLESS=1 cargo test -p pmsm-sim --lib schema"
        );
    }

    #[test]
    fn schema_files_are_generated_from_the_record() {
        check_file("period.proto", proto_text().as_bytes());
        check_file("period.desc", &file_descriptor_set());
        let mut json = serde_json::to_string_pretty(&json_schema()).unwrap_or_default();
        json.push('\n');
        check_file("period.schema.json", json.as_bytes());
    }

    /// Every key of a serialized sample is in the JSON schema with its type, and every key of
    /// the schema is in a serialized sample (with every optional part present); `null` is
    /// allowed exactly where a sample has it.
    #[test]
    fn json_schema_matches_the_sample() {
        fn walk(
            schema: &serde_json::Value,
            full: &serde_json::Value,
            bare: &serde_json::Value,
            path: &str,
        ) {
            let nullable = schema.get("anyOf").is_some();
            assert_eq!(
                nullable,
                bare.is_null(),
                "{path}: null in the schema and the sample"
            );
            let schema = schema.get("anyOf").map_or(schema, |any| &any[0]);
            if let Some(obj) = full.as_object() {
                let props = schema["properties"]
                    .as_object()
                    .unwrap_or_else(|| panic!("{path}: no properties in the schema"));
                let mut a: Vec<_> = obj.keys().collect();
                let mut b: Vec<_> = props.keys().collect();
                a.sort();
                b.sort();
                assert_eq!(a, b, "{path}");
                for (k, v) in obj {
                    let bare_v = bare.get(k).unwrap_or(&serde_json::Value::Null);
                    let bare_v = if bare.is_null() { v } else { bare_v };
                    walk(&props[k], v, bare_v, &format!("{path}.{k}"));
                }
            } else if let Some(a) = full.as_array() {
                assert_eq!(schema["type"], "array", "{path}");
                assert_eq!(schema["minItems"], a.len(), "{path}");
            } else if full.is_boolean() {
                assert_eq!(schema["type"], "boolean", "{path}");
            } else if full.is_string() {
                assert_eq!(schema["type"], "string", "{path}");
            } else if full.is_u64() {
                assert_eq!(schema["type"], "integer", "{path}");
            } else {
                assert_eq!(schema["type"], "number", "{path}");
            }
        }
        let full = full_sample();
        let bare = bare(full);
        let full = serde_json::to_value(full).unwrap_or_else(|e| panic!("{e}"));
        let bare = serde_json::to_value(bare).unwrap_or_else(|e| panic!("{e}"));
        walk(&json_schema(), &full, &bare, "");
    }

    /// Every field number is unique within its message, in order, and every message type
    /// exists; the descriptor set starts as a FileDescriptorSet with one file.
    #[test]
    fn table_is_consistent() {
        for m in MESSAGES {
            for w in m.fields.windows(2) {
                assert!(w[0].number < w[1].number, "{}.{}", m.name, w[1].name);
            }
            for fd in m.fields {
                assert!(
                    fd.number > 0 && fd.number < 1 << 29,
                    "{}.{}",
                    m.name,
                    fd.name
                );
                assert!(!fd.doc.is_empty(), "{}.{}: no doc", m.name, fd.name);
                if let Ty::Message(n) = fd.ty {
                    assert!(message_def(n).is_some(), "{}.{}: {n}", m.name, fd.name);
                }
            }
        }
        let set = file_descriptor_set();
        assert_eq!(set[0], 0x0a);
        assert_eq!(json_name("u_ab_commanded_v"), "uAbCommandedV");
    }
}

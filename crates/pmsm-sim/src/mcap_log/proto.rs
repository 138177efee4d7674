//! Protobuf encoding of the per-period message (`pmsm_sim.Period`), written by hand.
//!
//! The message is flat and fixed: doubles (`fixed64` on the wire), packed `repeated double`
//! arrays, bools, two strings and nested messages. Encoding it by hand costs about a fortieth
//! of a JSON encoding of the same numbers (60 ns), and Foxglove and the `mcap` Python package
//! (with `mcap-protobuf-support`) decode it from the schema the log carries: the
//! `FileDescriptorSet` that [`file_descriptor_set`] builds from [`MESSAGES`], the one table of
//! the schema. The same table prints the `.proto` text ([`proto_text`], checked in as
//! `src/schemas/period.proto`) and decodes a message back to JSON ([`decode_to_json`], for
//! tests and tools).
//!
//! Field names are those of the JSON encoding (the [`Sample`] serialized by serde), so the
//! Foxglove paths are the same in both (`/pmsm_sim/period.observer.angle_error_deg`,
//! `/pmsm_sim/period.truth.i_ab_a[0]`). Absent in the protobuf message where JSON has `null`:
//! `seed_filter`, `controller_observer`, `control.telemetry.estimate` (messages) and
//! `control.telemetry.speed_ref_rpm`, `control.telemetry.fault` (proto3 `optional`).

use crate::sim::{ObserverSample, Sample};

/// Package of the messages.
pub const PACKAGE: &str = "pmsm_sim";
/// Fully qualified name of the per-period message (the MCAP schema name).
pub const PERIOD_MESSAGE: &str = "pmsm_sim.Period";
/// File name inside the descriptor set.
pub const FILE_NAME: &str = "pmsm_sim/period.proto";

/// Type of a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    /// `double` (`fixed64` on the wire).
    Double,
    /// `uint64` (varint).
    Uint64,
    /// `bool` (varint).
    Bool,
    /// `string`.
    String,
    /// A message of this package, by its short name.
    Message(&'static str),
}

/// How a field may occur.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Card {
    /// A proto3 singular field (scalar: always written; message: absent means `null`).
    Single,
    /// proto3 `optional` (explicit presence: absent means `null`).
    Optional,
    /// `repeated` (packed for doubles).
    Repeated,
}

/// One field of a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldDef {
    /// Name (snake_case, as in the JSON encoding).
    pub name: &'static str,
    /// Field number.
    pub number: u32,
    /// Type.
    pub ty: Ty,
    /// Cardinality.
    pub card: Card,
    /// One line for the `.proto` text.
    pub doc: &'static str,
}

/// One message of the schema.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MessageDef {
    /// Short name (in package [`PACKAGE`]).
    pub name: &'static str,
    /// One line for the `.proto` text.
    pub doc: &'static str,
    /// Its fields, in field-number order.
    pub fields: &'static [FieldDef],
}

const fn f(name: &'static str, number: u32, ty: Ty, card: Card, doc: &'static str) -> FieldDef {
    FieldDef {
        name,
        number,
        ty,
        card,
        doc,
    }
}

use Card::{Optional, Repeated, Single};
use Ty::{Bool, Double, Message, String as Str, Uint64};

/// The schema: `pmsm_sim.Period` and the messages it uses (module docs).
#[rustfmt::skip]
pub const MESSAGES: &[MessageDef] = &[
    MessageDef {
        name: "Period",
        doc: "One PWM/control period k of a pmsm-sim run, at t_k = k Ts (SI units, electrical angles and speeds unless named _rpm).",
        fields: &[
            f("k", 1, Uint64, Single, "period index"),
            f("t_s", 2, Double, Single, "t_k = k Ts, s"),
            f("truth", 3, Message("Truth"), Single, "true plant state at t_k (scoring only)"),
            f("measured", 4, Message("Measured"), Single, "sensor outputs at t_k"),
            f("observer", 5, Message("ObserverSample"), Single, "the default EKF observer (ekf-core, f64)"),
            f("seed_filter", 6, Message("ObserverSample"), Single, "the seed's filter; absent when not run"),
            f("controller_observer", 7, Message("ObserverSample"), Single, "the controller's own observer (foc: its f32 EKF), scored like the others; absent without one"),
            f("control", 8, Message("Control"), Single, "the controller"),
            f("inverter", 9, Message("Inverter"), Single, "the inverter over [t_k, t_k+1)"),
        ],
    },
    MessageDef {
        name: "Truth",
        doc: "True plant state at t_k (a sensorless controller never sees it).",
        fields: &[
            f("theta_e_rad", 1, Double, Single, "electrical angle, rad, in [-pi, pi)"),
            f("omega_e_rad_s", 2, Double, Single, "electrical speed, rad/s"),
            f("speed_rpm", 3, Double, Single, "mechanical speed, rpm"),
            f("i_ab_a", 4, Double, Repeated, "stator currents [alpha, beta], A"),
            f("i_dq_a", 5, Double, Repeated, "stator currents [d, q] in the true rotor frame, A"),
            f("torque_nm", 6, Double, Single, "electromagnetic torque, N m"),
            f("load_torque_nm", 7, Double, Single, "load torque held over [t_k, t_k+1), N m"),
            f("psi_f_wb", 8, Double, Single, "the plant's flux linkage now (drifts with temperature), Wb"),
            f("rs_ohm", 9, Double, Single, "the plant's stator resistance now, ohm"),
        ],
    },
    MessageDef {
        name: "Measured",
        doc: "Sensor outputs at t_k.",
        fields: &[
            f("i_abc_a", 1, Double, Repeated, "measured phase currents [a, b, c] (c = -a - b), A"),
            f("i_ab_a", 2, Double, Repeated, "their Clarke transform [alpha, beta], A"),
            f("u_dc_v", 3, Double, Single, "measured DC-bus voltage, V"),
        ],
    },
    MessageDef {
        name: "ObserverSample",
        doc: "An observer's estimate at t_k with its errors against the truth.",
        fields: &[
            f("theta_e_rad", 1, Double, Single, "estimated electrical angle, rad"),
            f("omega_e_rad_s", 2, Double, Single, "estimated electrical speed, rad/s"),
            f("angle_error_deg", 3, Double, Single, "wrap(theta_hat - theta), electrical degrees"),
            f("speed_error_rad_s", 4, Double, Single, "omega_hat - omega_e, electrical rad/s"),
            f("p_diag", 5, Double, Repeated, "covariance diagonal: i_alpha (A^2), i_beta (A^2), omega_e ((rad/s)^2), theta (rad^2)"),
            f("nis", 6, Double, Single, "normalized innovation squared of the correction"),
            f("tracking", 7, Bool, Single, "status Tracking (angle standard deviation below the limit)"),
            f("psi_f_wb", 8, Double, Single, "tracked flux linkage, Wb (the configured one without tracking)"),
            f("psi_f_sigma_wb", 9, Double, Single, "its standard deviation, Wb (0 when not tracked)"),
            f("rs_ohm", 10, Double, Single, "stator resistance in use, ohm (tracked, or the configured one)"),
            f("rs_sigma_ohm", 11, Double, Single, "its standard deviation, ohm (0 when not tracked)"),
            f("winding_temperature_c", 12, Double, Single, "winding temperature derived from rs_ohm, deg C (NaN when not known)"),
        ],
    },
    MessageDef {
        name: "Control",
        doc: "The controller in period k.",
        fields: &[
            f("speed_ref_rpm", 1, Double, Single, "the scenario's mechanical speed reference, rpm"),
            f("duties", 2, Double, Repeated, "duties computed in this period [a, b, c]"),
            f("telemetry", 3, Message("Telemetry"), Single, "the controller's own report"),
        ],
    },
    MessageDef {
        name: "Telemetry",
        doc: "What the controller reports about itself.",
        fields: &[
            f("state", 1, Str, Single, "state name (sensored; foc: idle, align, open_loop, handover, closed_loop, fault)"),
            f("theta_e_rad", 2, Double, Single, "angle used for the Park transform, rad"),
            f("omega_e_rad_s", 3, Double, Single, "electrical speed used, rad/s"),
            f("i_dq_a", 4, Double, Repeated, "measured dq currents in the controller's frame, A"),
            f("i_dq_ref_a", 5, Double, Repeated, "dq current references, A"),
            f("u_dq_ref_v", 6, Double, Repeated, "dq voltage reference after limiting, V"),
            f("u_ab_ref_v", 7, Double, Repeated, "stationary voltage reference to the modulator, V"),
            f("voltage_limited", 8, Bool, Single, "voltage vector limited this period"),
            f("closed_loop", 9, Bool, Single, "the loops run on a rotor angle (sensored: always; foc: handover, closed_loop)"),
            f("speed_ref_rpm", 10, Double, Optional, "the controller's own (slewed) mechanical speed reference, rpm; absent if none or PWM off"),
            f("fault", 11, Str, Optional, "the latched fault name; absent if none"),
            f("estimate", 12, Message("ControllerEstimate"), Single, "the controller's own observer estimate; absent if none"),
        ],
    },
    MessageDef {
        name: "ControllerEstimate",
        doc: "The estimate of the observer inside the controller (foc: f32 EKF), after this period's correction.",
        fields: &[
            f("theta_e_rad", 1, Double, Single, "electrical angle, rad"),
            f("omega_e_rad_s", 2, Double, Single, "electrical speed, rad/s"),
            f("p_diag", 3, Double, Repeated, "covariance diagonal (i_alpha, i_beta, omega_e, theta)"),
            f("nis", 4, Double, Single, "normalized innovation squared"),
            f("tracking", 5, Bool, Single, "its status is Tracking"),
            f("psi_f_wb", 6, Double, Single, "tracked flux linkage, Wb"),
            f("psi_f_sigma_wb", 7, Double, Single, "its standard deviation, Wb"),
            f("rs_ohm", 8, Double, Single, "stator resistance in use, ohm"),
            f("rs_sigma_ohm", 9, Double, Single, "its standard deviation, ohm"),
            f("winding_temperature_c", 10, Double, Single, "winding temperature derived from rs_ohm, deg C"),
        ],
    },
    MessageDef {
        name: "Inverter",
        doc: "The inverter over [t_k, t_k+1).",
        fields: &[
            f("pwm_enabled", 1, Bool, Single, "the bridge switches (false: all switches open, voltages 0)"),
            f("duties", 2, Double, Repeated, "duties applied (the previous period's with the computation delay)"),
            f("u_ab_v", 3, Double, Repeated, "stator voltage actually applied, dead time included, V"),
            f("u_ab_commanded_v", 4, Double, Repeated, "ideal voltage of the applied duties on the measured bus (the observer's input at k+1), V"),
            f("u_dc_v", 5, Double, Single, "DC-bus voltage, V"),
        ],
    },
];

// ---------------------------------------------------------------------------------------------
// Wire format.

const WT_VARINT: u32 = 0;
const WT_I64: u32 = 1;
const WT_LEN: u32 = 2;

/// Bytes of a `pmsm_sim.Period` message besides its two strings, at most (the largest is
/// about 700; a unit test keeps the margin).
const PERIOD_MAX_FIXED: usize = 1536;

/// A message under construction in a buffer that is long enough (the caller sizes it): no
/// capacity checks per field, the position in a register.
struct Enc<'a> {
    out: &'a mut [u8],
    pos: usize,
}

impl Enc<'_> {
    #[inline(always)]
    fn byte(&mut self, b: u8) {
        self.out[self.pos] = b;
        self.pos += 1;
    }

    /// Eight bytes (a double), a fixed-size copy.
    #[inline(always)]
    fn le8(&mut self, v: [u8; 8]) {
        let p = self.pos;
        self.out[p..p + 8].copy_from_slice(&v);
        self.pos = p + 8;
    }

    #[inline]
    fn bytes(&mut self, b: &[u8]) {
        let end = self.pos + b.len();
        self.out[self.pos..end].copy_from_slice(b);
        self.pos = end;
    }

    #[inline(always)]
    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.byte((v as u8) | 0x80);
            v >>= 7;
        }
        self.byte(v as u8);
    }

    #[inline(always)]
    fn key(&mut self, field: u32, wire_type: u32) {
        let k = (field << 3) | wire_type;
        if k < 0x80 {
            self.byte(k as u8);
        } else {
            self.varint(u64::from(k));
        }
    }

    #[inline(always)]
    fn double(&mut self, field: u32, v: f64) {
        self.key(field, WT_I64);
        self.le8(v.to_le_bytes());
    }

    #[inline(always)]
    fn uint64(&mut self, field: u32, v: u64) {
        self.key(field, WT_VARINT);
        self.varint(v);
    }

    #[inline(always)]
    fn bool(&mut self, field: u32, v: bool) {
        self.key(field, WT_VARINT);
        self.byte(u8::from(v));
    }

    #[inline]
    fn string(&mut self, field: u32, s: &str) {
        self.key(field, WT_LEN);
        self.varint(s.len() as u64);
        self.bytes(s.as_bytes());
    }

    /// Packed `repeated double` (at most 15 values: a one-byte length).
    #[inline(always)]
    fn doubles<const N: usize>(&mut self, field: u32, v: &[f64; N]) {
        const { assert!(N * 8 < 0x80) };
        self.key(field, WT_LEN);
        self.byte((N * 8) as u8);
        for x in v {
            self.le8(x.to_le_bytes());
        }
    }

    /// A nested message whose body is shorter than 128 bytes, as a rule: one byte is reserved
    /// for the length, patched in after `body` wrote it.
    #[inline(always)]
    fn message(&mut self, field: u32, body: impl FnOnce(&mut Self)) {
        self.key(field, WT_LEN);
        let at = self.pos;
        self.pos += 1;
        body(self);
        let len = self.pos - at - 1;
        if len < 0x80 {
            self.out[at] = len as u8;
        } else {
            self.fix_len(at, 1);
        }
    }

    /// A nested message whose body is 128 to 16383 bytes long, as a rule: two length bytes.
    #[inline(always)]
    fn long_message(&mut self, field: u32, body: impl FnOnce(&mut Self)) {
        self.key(field, WT_LEN);
        let at = self.pos;
        self.pos += 2;
        body(self);
        let len = self.pos - at - 2;
        if (0x80..0x4000).contains(&len) {
            self.out[at] = (len as u8) | 0x80;
            self.out[at + 1] = (len >> 7) as u8;
        } else {
            self.fix_len(at, 2);
        }
    }

    /// Writes the length of the body that follows the `reserved` bytes at `at` when it needs
    /// another number of bytes, moving the body.
    #[cold]
    #[inline(never)]
    fn fix_len(&mut self, at: usize, reserved: usize) {
        let len = self.pos - at - reserved;
        let mut l = Enc {
            out: &mut [0u8; 10],
            pos: 0,
        };
        l.varint(len as u64);
        let n = l.pos;
        self.out.copy_within(at + reserved..self.pos, at + n);
        self.pos = self.pos + n - reserved;
        self.out[at..at + n].copy_from_slice(&l.out[..n]);
    }
}

/// Encodes into `buf` (grown to `capacity` bytes if shorter, never cleared) and returns the
/// length written.
fn encode_into(buf: &mut Vec<u8>, capacity: usize, body: impl FnOnce(&mut Enc<'_>)) -> usize {
    if buf.len() < capacity {
        buf.resize(capacity, 0);
    }
    let mut e = Enc { out: buf, pos: 0 };
    body(&mut e);
    e.pos
}

/// Encodes a whole message into a new vector (`capacity`: an upper bound of its size).
fn encode_vec(capacity: usize, body: impl FnOnce(&mut Enc<'_>)) -> Vec<u8> {
    let mut buf = Vec::new();
    let n = encode_into(&mut buf, capacity, body);
    buf.truncate(n);
    buf
}

fn observer(e: &mut Enc<'_>, o: &ObserverSample) {
    e.double(1, o.theta_e_rad);
    e.double(2, o.omega_e_rad_s);
    e.double(3, o.angle_error_deg);
    e.double(4, o.speed_error_rad_s);
    e.doubles(5, &o.p_diag);
    e.double(6, o.nis);
    e.bool(7, o.tracking);
    e.double(8, o.psi_f_wb);
    e.double(9, o.psi_f_sigma_wb);
    e.double(10, o.rs_ohm);
    e.double(11, o.rs_sigma_ohm);
    e.double(12, o.winding_temperature_c);
}

/// Encodes the `pmsm_sim.Period` message of a sample (the field numbers of [`MESSAGES`]; a
/// unit test decodes it back with the table) into a reused buffer.
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
    pub fn encode(&mut self, s: &Sample) -> &[u8] {
        let tel = &s.control.telemetry;
        let cap = PERIOD_MAX_FIXED + tel.state.len() + tel.fault.map_or(0, str::len);
        let n = encode_into(&mut self.buf, cap, |e| encode_period(e, s));
        &self.buf[..n]
    }
}

fn encode_period(e: &mut Enc<'_>, s: &Sample) {
    e.uint64(1, s.k);
    e.double(2, s.t_s);
    e.message(3, |e| {
        let t = &s.truth;
        e.double(1, t.theta_e_rad);
        e.double(2, t.omega_e_rad_s);
        e.double(3, t.speed_rpm);
        e.doubles(4, &t.i_ab_a);
        e.doubles(5, &t.i_dq_a);
        e.double(6, t.torque_nm);
        e.double(7, t.load_torque_nm);
        e.double(8, t.psi_f_wb);
        e.double(9, t.rs_ohm);
    });
    e.message(4, |e| {
        let m = &s.measured;
        e.doubles(1, &m.i_abc_a);
        e.doubles(2, &m.i_ab_a);
        e.double(3, m.u_dc_v);
    });
    e.message(5, |e| observer(e, &s.observer));
    if let Some(o) = &s.seed_filter {
        e.message(6, |e| observer(e, o));
    }
    if let Some(o) = &s.controller_observer {
        e.message(7, |e| observer(e, o));
    }
    e.long_message(8, |e| {
        let c = &s.control;
        e.double(1, c.speed_ref_rpm);
        e.doubles(2, &c.duties);
        e.long_message(3, |e| {
            let t = &c.telemetry;
            e.string(1, t.state);
            e.double(2, t.theta_e_rad);
            e.double(3, t.omega_e_rad_s);
            e.doubles(4, &t.i_dq_a);
            e.doubles(5, &t.i_dq_ref_a);
            e.doubles(6, &t.u_dq_ref_v);
            e.doubles(7, &t.u_ab_ref_v);
            e.bool(8, t.voltage_limited);
            e.bool(9, t.closed_loop);
            if let Some(w) = t.speed_ref_rpm {
                e.double(10, w);
            }
            if let Some(f) = t.fault {
                e.string(11, f);
            }
            if let Some(est) = &t.estimate {
                e.message(12, |e| {
                    e.double(1, est.theta_e_rad);
                    e.double(2, est.omega_e_rad_s);
                    e.doubles(3, &est.p_diag);
                    e.double(4, est.nis);
                    e.bool(5, est.tracking);
                    e.double(6, est.psi_f_wb);
                    e.double(7, est.psi_f_sigma_wb);
                    e.double(8, est.rs_ohm);
                    e.double(9, est.rs_sigma_ohm);
                    e.double(10, est.winding_temperature_c);
                });
            }
        });
    });
    e.message(9, |e| {
        let i = &s.inverter;
        e.bool(1, i.pwm_enabled);
        e.doubles(2, &i.duties);
        e.doubles(3, &i.u_ab_v);
        e.doubles(4, &i.u_ab_commanded_v);
        e.double(5, i.u_dc_v);
    });
}

// ---------------------------------------------------------------------------------------------
// The schema as a FileDescriptorSet (google/protobuf/descriptor.proto), and as .proto text.

fn message_def(name: &str) -> Option<&'static MessageDef> {
    MESSAGES.iter().find(|m| m.name == name)
}

/// The `FileDescriptorSet` of the schema (one file, `proto3`, package [`PACKAGE`]): the MCAP
/// schema data of encoding `protobuf`. Byte for byte what `protoc --descriptor_set_out`
/// writes for `src/schemas/period.proto` (checked in as `src/schemas/period.desc`, a unit test
/// compares).
pub fn file_descriptor_set() -> Vec<u8> {
    // Generous: the set is about 3 KB (a unit test keeps it under 16 KB).
    const CAP: usize = 64 << 10;
    // FileDescriptorSet: file 1.
    encode_vec(CAP, |e| {
        e.message(1, |e| {
            // FileDescriptorProto: name 1, package 2, message_type 4, syntax 12.
            e.string(1, FILE_NAME);
            e.string(2, PACKAGE);
            for m in MESSAGES {
                e.message(4, |e| descriptor_proto(e, m));
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
        e.message(2, |e| {
            e.string(1, fd.name);
            e.uint64(3, u64::from(fd.number));
            e.uint64(4, if fd.card == Repeated { 3 } else { 1 });
            let ty = match fd.ty {
                Double => 1,
                Uint64 => 4,
                Bool => 8,
                Str => 9,
                Message(_) => 11,
            };
            e.uint64(5, ty);
            if let Message(name) = fd.ty {
                e.string(6, &format!(".{PACKAGE}.{name}"));
            }
            if fd.card == Optional {
                e.uint64(9, oneofs);
                oneofs += 1;
            }
            e.string(10, &json_name(fd.name));
            if fd.card == Optional {
                e.bool(17, true);
            }
        });
    }
    // The synthetic oneofs of the proto3 `optional` fields (there is no real oneof).
    for fd in m.fields.iter().filter(|fd| fd.card == Optional) {
        e.message(8, |e| e.string(1, &format!("_{}", fd.name)));
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
    s.push_str(
        "// Generated from the table in crates/pmsm-sim/src/mcap_log/proto.rs (a unit test\n",
    );
    s.push_str(
        "// checks that this file matches it); the log carries it as a FileDescriptorSet.\n",
    );
    s.push_str("syntax = \"proto3\";\n\n");
    s.push_str(&format!("package {PACKAGE};\n"));
    for m in MESSAGES {
        s.push_str(&format!("\n// {}\nmessage {} {{\n", m.doc, m.name));
        for fd in m.fields {
            let ty = match fd.ty {
                Double => "double",
                Uint64 => "uint64",
                Bool => "bool",
                Str => "string",
                Message(n) => n,
            };
            let label = match fd.card {
                Single => "",
                Optional => "optional ",
                Repeated => "repeated ",
            };
            s.push_str(&format!(
                "  {label}{ty} {} = {};  // {}\n",
                fd.name, fd.number, fd.doc
            ));
        }
        s.push_str("}\n");
    }
    s
}

// ---------------------------------------------------------------------------------------------
// Decoding (tests, tools).

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

/// Decodes a message of the schema (short name, e.g. `"Period"`) into JSON with the field
/// names of the schema: absent messages and `optional` fields are `null`, absent scalars
/// their proto3 default. Unknown fields are skipped.
pub fn decode_to_json(message: &str, bytes: &[u8]) -> Result<serde_json::Value, String> {
    use serde_json::{Map, Value};
    let def = message_def(message).ok_or_else(|| format!("no message {message}"))?;
    let mut out = Map::new();
    for fd in def.fields {
        let v = match (fd.card, fd.ty) {
            (Repeated, _) => Value::Array(Vec::new()),
            (Optional, _) | (_, Message(_)) => Value::Null,
            (_, Double) => Value::from(0.0),
            (_, Uint64) => Value::from(0u64),
            (_, Bool) => Value::Bool(false),
            (_, Str) => Value::from(""),
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
                    let n = read_varint(bytes, &mut pos)? as usize;
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
        let value = match (fd.ty, wt) {
            (Double, WT_I64) => Value::from(f64_at(take(bytes, &mut pos, 8)?)),
            (Double, WT_LEN) if fd.card == Repeated => {
                let n = read_varint(bytes, &mut pos)? as usize;
                let body = take(bytes, &mut pos, n)?;
                if !n.is_multiple_of(8) {
                    return Err(format!("{message}.{name}: packed length {n}"));
                }
                let vals: Vec<Value> = body.chunks(8).map(|c| Value::from(f64_at(c))).collect();
                if let Some(Value::Array(a)) = out.get_mut(name) {
                    a.extend(vals);
                }
                continue;
            }
            (Uint64, WT_VARINT) => Value::from(read_varint(bytes, &mut pos)?),
            (Bool, WT_VARINT) => Value::Bool(read_varint(bytes, &mut pos)? != 0),
            (Str, WT_LEN) => {
                let n = read_varint(bytes, &mut pos)? as usize;
                let s = std::str::from_utf8(take(bytes, &mut pos, n)?)
                    .map_err(|e| format!("{message}.{name}: {e}"))?;
                Value::from(s)
            }
            (Message(m), WT_LEN) => {
                let n = read_varint(bytes, &mut pos)? as usize;
                decode_to_json(m, take(bytes, &mut pos, n)?)?
            }
            _ => return Err(format!("{message}.{name}: unexpected wire type {wt}")),
        };
        if fd.card == Repeated {
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
    use crate::controller::ControllerEstimate;

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
        s.truth.psi_f_wb = next();
        s.truth.rs_ohm = next();
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
            psi_f_wb: next(),
            psi_f_sigma_wb: next(),
            rs_ohm: next(),
            rs_sigma_ohm: next(),
            winding_temperature_c: next(),
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
        let mut bare = full;
        bare.seed_filter = None;
        bare.controller_observer = None;
        bare.control.telemetry.speed_ref_rpm = None;
        bare.control.telemetry.fault = None;
        bare.control.telemetry.estimate = None;
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
            e.message(3, |e| {
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
        let buf = encode_vec(64, |e| e.long_message(3, |e| e.bool(2, true)));
        assert_eq!(buf, [0x1a, 2, 0x10, 1]);
        // A body of 2^14 bytes or more needs three.
        let buf = encode_vec(1 << 16, |e| e.long_message(3, |e| e.bytes(&[7; 20_000])));
        assert_eq!(&buf[..5], &[0x1a, 0xa0, 0x9c, 0x01, 7]);
        assert_eq!(buf.len(), 4 + 20_000);
    }

    /// The default's message is about 900 bytes (what the log size per period is made of;
    /// 700 before the tracked parameters), well within the buffer reserved for it.
    #[test]
    fn message_size() {
        let mut s = full_sample();
        let mut enc = PeriodEncoder::new();
        let n = enc.encode(&s).len();
        assert!((800..1000).contains(&n), "{n}");
        s.control.telemetry.state = "";
        s.control.telemetry.fault = None;
        s.k = u64::MAX;
        assert!(enc.encode(&s).len() + 128 < PERIOD_MAX_FIXED);
        // Long names grow the buffer.
        let long: &'static str = "x".repeat(5000).leak();
        s.control.telemetry.state = long;
        s.control.telemetry.fault = Some(long);
        let decoded = decode_to_json("Period", enc.encode(&s)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(decoded["control"]["telemetry"]["fault"], long);
        assert!(file_descriptor_set().len() < 16 << 10);
    }

    #[test]
    fn the_checked_in_proto_file_matches_the_table() {
        let file = include_str!("../schemas/period.proto");
        assert_eq!(
            file,
            proto_text(),
            "src/schemas/period.proto is stale: write proto_text() to it"
        );
    }

    /// The descriptor set is protoc's for the checked-in `.proto` file (protoc 3.21), byte for
    /// byte. After a change of the table, regenerate it (from the crate's directory):
    /// `mkdir -p /tmp/p/pmsm_sim && cp src/schemas/period.proto /tmp/p/pmsm_sim/ &&
    /// protoc -I /tmp/p --descriptor_set_out=src/schemas/period.desc pmsm_sim/period.proto`.
    #[test]
    fn the_descriptor_set_is_protocs() {
        let protoc: &[u8] = include_bytes!("../schemas/period.desc");
        assert_eq!(file_descriptor_set(), protoc);
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
                assert!(fd.number < 16, "one-byte keys: {}.{}", m.name, fd.name);
                if let Message(n) = fd.ty {
                    assert!(message_def(n).is_some(), "{}.{}: {n}", m.name, fd.name);
                }
            }
        }
        let set = file_descriptor_set();
        assert_eq!(set[0], 0x0a);
        assert_eq!(json_name("u_ab_commanded_v"), "uAbCommandedV");
    }
}

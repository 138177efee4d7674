//! The per-period record of a run, [`Sample`], and its schema: **the one place** where the
//! record is described.
//!
//! Each message below is written once, in [`record!`](crate::output::record) form. From that one
//! description the macro makes
//!
//! - the Rust struct (with `serde::Serialize`: the JSON encoding of the log, field names as
//!   written here),
//! - its protobuf encoding ([`crate::output::mcap::proto::PeriodEncoder`]: straight-line code,
//!   field numbers as written here),
//! - its entry in the schema table [`MESSAGES`], from which [`crate::output::mcap::proto`] builds
//!   the `FileDescriptorSet` the log carries, the `.proto` text, the JSON schema, and the one
//!   decoder (protobuf -> JSON value) that the tuner, the tests and the tools use.
//!
//! The checked-in `src/schemas/period.proto`, `period.desc` and `period.schema.json` are
//! generated from the table; unit tests fail when they are stale.
//!
//! # Adding a field
//!
//! 1. Add one line to the message below, at its end, with the **next unused field number**
//!    of that message and a doc comment (it becomes the rustdoc, the `.proto` comment and
//!    the JSON schema's description):
//!    ```text
//!    /// Tracked flux linkage, Wb.
//!    pub psi_f_wb: f64 = 8,
//!    ```
//!    Field types: `f64`, `u64`, `bool`, `&'static str`, `[f64; N]` (a packed
//!    `repeated double` of `N` values), `Option<f64>` and `Option<&'static str>` (proto3
//!    `optional`, `null` in JSON when absent), another message of this module, or
//!    `Option<Message>` (absent when `None`). Never renumber or reuse a number: logs written
//!    before still decode (a field they lack reads as its proto3 default: 0, `false`, `""`,
//!    `[]`, or `null`).
//! 2. Fill it where the record is made: `sim.rs` for the run's fields; for an observer's
//!    field (e.g. a tracked parameter), add it to [`ControllerEstimate`] as well (what every
//!    observer returns, [`crate::drive::rotor_observers::ObserverEstimate`], and what a controller reports
//!    of its own), set it in the [`crate::drive::rotor_observers::Observer`] impls and in `foc_drive.rs`, and
//!    copy it in [`ObserverSample::from_controller`]. The compiler names every struct literal
//!    that lacks it.
//! 3. Regenerate the checked-in schema files:
//!    `PMSM_SIM_BLESS=1 cargo test -p pmsm-sim --lib schema` (then review the diff of
//!    `src/schemas/`).
//!
//! A vector's components can be written as named scalars too, for plots: `named { i_d_a = 12
//! => i_dq_a[0], ... }` ends the message. Computed from the array when encoded, they are in the
//! JSON encoding, the schema and the decoded logs, never out of step with the array.
//!
//! Nothing else: the encoder, the descriptor, the JSON schema and the decoder follow. A new
//! message is one more `record!` block (and its name in the [`MESSAGES`] list).
//!
//! # Module graph
//!
//! This module is at the bottom of the simulator: it depends on `ekf-core` only (for
//! `wrap_angle`); the run loop, the metrics, the log, the plot and the suites
//! depend on it.

use ekf_core::wrap_angle;
use serde::{Serialize, ser::SerializeStruct};

// ---------------------------------------------------------------------------------------------
// The schema table.

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
    /// A message of this package, by its short (protobuf) name.
    Message(&'static str),
}

/// How a field may occur.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Card {
    /// A proto3 singular field (scalar: always written; message: absent means `null`).
    Single,
    /// proto3 `optional` (explicit presence: absent means `null`).
    Optional,
    /// `repeated` (packed for doubles), with a fixed length in this record.
    Repeated(usize),
}

/// One field of a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldDef {
    /// Name (snake_case, as in the JSON encoding and the Rust struct).
    pub name: &'static str,
    /// Field number.
    pub number: u32,
    /// Type.
    pub ty: Ty,
    /// Cardinality.
    pub card: Card,
    /// `null` in the JSON encoding when absent (an `Option` in the record: proto3 `optional`
    /// scalars and messages that may be left out).
    pub nullable: bool,
    /// Doc comment, line by line.
    pub doc: &'static [&'static str],
}

/// One message of the schema.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MessageDef {
    /// Short protobuf name (in package `pmsm_sim`).
    pub name: &'static str,
    /// Doc comment, line by line.
    pub doc: &'static [&'static str],
    /// Its fields, in field-number order.
    pub fields: &'static [FieldDef],
}

impl MessageDef {
    /// The doc comment as one line.
    pub fn doc_line(&self) -> String {
        doc_line(self.doc)
    }
}

impl FieldDef {
    /// The doc comment as one line.
    pub fn doc_line(&self) -> String {
        doc_line(self.doc)
    }
}

fn doc_line(lines: &[&str]) -> String {
    let words: Vec<&str> = lines.iter().map(|l| l.trim()).collect();
    words.join(" ").replace('`', "")
}

/// Every message of the record, the top one ([`Sample`], `Period`) first.
pub const MESSAGES: &[MessageDef] = &[
    <Sample as Message>::DEF,
    <Truth as Message>::DEF,
    <Measured as Message>::DEF,
    <ObserverSample as Message>::DEF,
    <ControlRecord as Message>::DEF,
    <ControllerTelemetry as Message>::DEF,
    <ControllerEstimate as Message>::DEF,
    <InverterRecord as Message>::DEF,
];

/// The table entry of a message by its protobuf name.
pub fn message_def(name: &str) -> Option<&'static MessageDef> {
    MESSAGES.iter().find(|m| m.name == name)
}

// ---------------------------------------------------------------------------------------------
// Protobuf wire format: the encoder every message uses.

pub(crate) const WT_VARINT: u32 = 0;
pub(crate) const WT_I64: u32 = 1;
pub(crate) const WT_LEN: u32 = 2;

/// A message under construction in a buffer that is long enough (the caller sizes it with
/// [`Message::MAX_BODY`] and [`Message::text_len`]): no capacity checks per field.
pub(crate) struct Enc<'a> {
    pub(crate) out: &'a mut [u8],
    pub(crate) pos: usize,
}

impl Enc<'_> {
    #[inline(always)]
    pub(crate) fn byte(&mut self, b: u8) {
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
    pub(crate) fn bytes(&mut self, b: &[u8]) {
        let end = self.pos + b.len();
        self.out[self.pos..end].copy_from_slice(b);
        self.pos = end;
    }

    #[inline(always)]
    pub(crate) fn varint(&mut self, mut v: u64) {
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

    /// A `double` field: key and value in one nine-byte copy when the key is one byte (field
    /// numbers up to 15, every field of the record), one bounds check per field.
    #[inline(always)]
    pub(crate) fn double(&mut self, field: u32, v: f64) {
        let k = (field << 3) | WT_I64;
        if k < 0x80 {
            let b = v.to_le_bytes();
            let p = self.pos;
            self.out[p..p + 9]
                .copy_from_slice(&[k as u8, b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]);
            self.pos = p + 9;
        } else {
            self.key(field, WT_I64);
            self.le8(v.to_le_bytes());
        }
    }

    #[inline(always)]
    pub(crate) fn uint64(&mut self, field: u32, v: u64) {
        self.key(field, WT_VARINT);
        self.varint(v);
    }

    #[inline(always)]
    pub(crate) fn bool(&mut self, field: u32, v: bool) {
        let k = (field << 3) | WT_VARINT;
        if k < 0x80 {
            let p = self.pos;
            self.out[p..p + 2].copy_from_slice(&[k as u8, u8::from(v)]);
            self.pos = p + 2;
        } else {
            self.key(field, WT_VARINT);
            self.byte(u8::from(v));
        }
    }

    #[inline]
    pub(crate) fn string(&mut self, field: u32, s: &str) {
        self.key(field, WT_LEN);
        self.varint(s.len() as u64);
        self.bytes(s.as_bytes());
    }

    /// Packed `repeated double` (at most 15 values: a one-byte length).
    #[inline(always)]
    fn doubles<const N: usize>(&mut self, field: u32, v: &[f64; N]) {
        const { assert!(N * 8 < 0x80) };
        let k = (field << 3) | WT_LEN;
        if k >= 0x80 {
            self.key(field, WT_LEN);
            self.byte((N * 8) as u8);
            for x in v {
                self.le8(x.to_le_bytes());
            }
            return;
        }
        // One bounds check for the field: key, length, the values.
        let p = self.pos;
        let out = &mut self.out[p..p + 2 + 8 * N];
        out[0] = k as u8;
        out[1] = (N * 8) as u8;
        for (dst, x) in out[2..].chunks_exact_mut(8).zip(v) {
            dst.copy_from_slice(&x.to_le_bytes());
        }
        self.pos = p + 2 + 8 * N;
    }

    /// A nested message: one length byte reserved (`RESERVE = 1`, a body that is shorter than
    /// 128 bytes as a rule) or two (128 to 16383 bytes), patched in after `body` wrote it; a
    /// body of another length is moved ([`Self::fix_len`]).
    #[inline(always)]
    pub(crate) fn message<const RESERVE: usize>(
        &mut self,
        field: u32,
        body: impl FnOnce(&mut Self),
    ) {
        self.key(field, WT_LEN);
        let at = self.pos;
        self.pos += RESERVE;
        body(self);
        let len = self.pos - at - RESERVE;
        if RESERVE == 1 && len < 0x80 {
            self.out[at] = len as u8;
        } else if RESERVE == 2 && (0x80..0x4000).contains(&len) {
            self.out[at] = (len as u8) | 0x80;
            self.out[at + 1] = (len >> 7) as u8;
        } else {
            self.fix_len(at, RESERVE);
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
pub(crate) fn encode_into(
    buf: &mut Vec<u8>,
    capacity: usize,
    body: impl FnOnce(&mut Enc<'_>),
) -> usize {
    if buf.len() < capacity {
        buf.resize(capacity, 0);
    }
    let mut e = Enc { out: buf, pos: 0 };
    body(&mut e);
    e.pos
}

/// A type that can be a field of a record message.
pub(crate) trait Field {
    /// Protobuf type.
    const TY: Ty;
    /// Cardinality.
    const CARD: Card;
    /// Most bytes of the field's value on the wire (its key and text aside).
    const MAX_LEN: usize;
    /// May be absent (`None`, `null` in JSON).
    const NULLABLE: bool = false;
    /// Writes the field (nothing when absent).
    fn encode(&self, e: &mut Enc<'_>, number: u32);
    /// Bytes of text (strings) in the field.
    #[inline(always)]
    fn text_len(&self) -> usize {
        0
    }
}

/// A message of the record.
pub(crate) trait Message {
    /// Its table entry.
    const DEF: MessageDef;
    /// Most bytes of its body, text aside.
    const MAX_BODY: usize;
    /// Writes the fields.
    fn encode_body(&self, e: &mut Enc<'_>);
    /// Bytes of text (strings) in the message.
    fn text_len(&self) -> usize;
}

impl Field for f64 {
    const TY: Ty = Ty::Double;
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = 8;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        e.double(number, *self);
    }
}

impl Field for u64 {
    const TY: Ty = Ty::Uint64;
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = 10;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        e.uint64(number, *self);
    }
}

impl Field for bool {
    const TY: Ty = Ty::Bool;
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = 1;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        e.bool(number, *self);
    }
}

impl Field for &'static str {
    const TY: Ty = Ty::String;
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = 10;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        e.string(number, self);
    }
    #[inline(always)]
    fn text_len(&self) -> usize {
        self.len()
    }
}

impl<const N: usize> Field for [f64; N] {
    const TY: Ty = Ty::Double;
    const CARD: Card = Card::Repeated(N);
    const MAX_LEN: usize = 1 + 8 * N;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        e.doubles(number, self);
    }
}

impl Field for Option<f64> {
    const TY: Ty = Ty::Double;
    const CARD: Card = Card::Optional;
    const MAX_LEN: usize = 8;
    const NULLABLE: bool = true;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        if let Some(v) = self {
            e.double(number, *v);
        }
    }
}

impl Field for Option<&'static str> {
    const TY: Ty = Ty::String;
    const CARD: Card = Card::Optional;
    const MAX_LEN: usize = 10;
    const NULLABLE: bool = true;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        if let Some(s) = self {
            e.string(number, s);
        }
    }
    #[inline(always)]
    fn text_len(&self) -> usize {
        self.map_or(0, str::len)
    }
}

/// Bytes of the key of field `number` (any wire type).
const fn key_len(number: u32) -> usize {
    let k = number << 3;
    if k < 0x80 {
        1
    } else if k < 0x4000 {
        2
    } else {
        5
    }
}

/// Length bytes reserved for a nested message of at most `max_body` bytes (text aside).
const fn reserve(max_body: usize) -> usize {
    if max_body < 0x80 { 1 } else { 2 }
}

#[inline(always)]
fn encode_nested<M: Message>(m: &M, e: &mut Enc<'_>, number: u32) {
    if reserve(M::MAX_BODY) == 1 {
        e.message::<1>(number, |e| m.encode_body(e));
    } else {
        e.message::<2>(number, |e| m.encode_body(e));
    }
}

impl<M: Message> Field for M {
    const TY: Ty = Ty::Message(M::DEF.name);
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = reserve(M::MAX_BODY) + M::MAX_BODY;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        encode_nested(self, e, number);
    }
    #[inline(always)]
    fn text_len(&self) -> usize {
        Message::text_len(self)
    }
}

impl<M: Message> Field for Option<M> {
    const TY: Ty = Ty::Message(M::DEF.name);
    const CARD: Card = Card::Single;
    const MAX_LEN: usize = reserve(M::MAX_BODY) + M::MAX_BODY;
    const NULLABLE: bool = true;
    #[inline(always)]
    fn encode(&self, e: &mut Enc<'_>, number: u32) {
        if let Some(m) = self {
            encode_nested(m, e, number);
        }
    }
    #[inline(always)]
    fn text_len(&self) -> usize {
        self.as_ref().map_or(0, Message::text_len)
    }
}

/// Defines a message of the record: the struct, its encoding and its table entry (module
/// docs). Syntax: doc comments, `pub struct RustName as "ProtoName" { fields }`, each field
/// `/// doc` `pub name: Type = number,`.
macro_rules! record {
    (
        $(#[doc = $doc:literal])*
        pub struct $name:ident as $proto:literal {
            $(
                $(#[doc = $fdoc:literal])*
                pub $field:ident : $ty:ty = $number:literal,
            )*
            $(named { $($named:ident = $nnumber:literal => $src:ident[$idx:literal],)* })?
        }
    ) => {
        $(#[doc = $doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct $name {
            $(
                $(#[doc = $fdoc])*
                pub $field: $ty,
            )*
        }

        impl Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_struct($proto, Self::DEF.fields.len())?;
                $(m.serialize_field(stringify!($field), &self.$field)?;)*
                $($(m.serialize_field(stringify!($named), &self.$src[$idx])?;)*)?
                m.end()
            }
        }

        impl Message for $name {
            const DEF: MessageDef = MessageDef {
                name: $proto,
                doc: &[$($doc),*],
                fields: &[$(FieldDef {
                    name: stringify!($field),
                    number: $number,
                    ty: <$ty as Field>::TY,
                    card: <$ty as Field>::CARD,
                    nullable: <$ty as Field>::NULLABLE,
                    doc: &[$($fdoc),*],
                }),* $($(, FieldDef {
                    name: stringify!($named),
                    number: $nnumber,
                    ty: Ty::Double,
                    card: Card::Single,
                    nullable: false,
                    doc: &[concat!("`", stringify!($src), "[", $idx, "]` again, named (for plots).")],
                })*)?],
            };
            const MAX_BODY: usize = 0 $(+ key_len($number) + <$ty as Field>::MAX_LEN)*
                $($(+ key_len($nnumber) + 8)*)?;
            #[inline(always)]
            fn encode_body(&self, e: &mut Enc<'_>) {
                $(Field::encode(&self.$field, e, $number);)*
                $($(e.double($nnumber, self.$src[$idx]);)*)?
            }
            #[inline(always)]
            fn text_len(&self) -> usize {
                0 $(+ Field::text_len(&self.$field))*
            }
        }
    };
}

// ---------------------------------------------------------------------------------------------
// The record.

record! {
    /// Everything recorded for period `k` (at `t_k = k Ts`; SI units, electrical angles and
    /// speeds unless named `_rpm`).
    pub struct Sample as "Period" {
        /// Period index.
        pub k: u64 = 1,
        /// `t_k = k Ts`, s.
        pub t_s: f64 = 2,
        /// True plant state at `t_k` (scoring only).
        pub truth: Truth = 3,
        /// Sensor outputs at `t_k`.
        pub measured: Measured = 4,
        /// The project's default observer (ekf-core `ObserverConfig::new`, lag-free, f64).
        pub observer: ObserverSample = 5,
        /// The seed's filter (`ObserverConfig::seed`); absent (`null`) when not run.
        pub seed_filter: Option<ObserverSample> = 6,
        /// The controller's own observer (for foc: its f32 EKF, the one that closes the
        /// loop), scored like the others; absent (`null`) for a controller without one.
        pub controller_observer: Option<ObserverSample> = 7,
        /// The controller.
        pub control: ControlRecord = 8,
        /// The inverter over `[t_k, t_k+1)`.
        pub inverter: InverterRecord = 9,
    }
}

record! {
    /// The true state at `t_k` (for scoring and the log; a sensorless controller never sees
    /// it).
    pub struct Truth as "Truth" {
        /// Electrical angle, rad, in `[-pi, pi)`.
        pub theta_e_rad: f64 = 1,
        /// Electrical speed, rad/s.
        pub omega_e_rad_s: f64 = 2,
        /// Mechanical speed, rpm.
        pub speed_rpm: f64 = 3,
        /// Stator currents `[alpha, beta]`, A.
        pub i_ab_a: [f64; 2] = 4,
        /// Stator currents `[d, q]` in the true rotor frame, A.
        pub i_dq_a: [f64; 2] = 5,
        /// Electromagnetic torque, N m.
        pub torque_nm: f64 = 6,
        /// Load torque held over `[t_k, t_k+1)`, N m.
        pub load_torque_nm: f64 = 7,
        /// The plant's flux linkage now (drifts with temperature, module `faults`), Wb.
        pub psi_f_wb: f64 = 8,
        /// The plant's stator resistance now, ohm.
        pub rs_ohm: f64 = 9,
        named {
            i_alpha_a = 10 => i_ab_a[0], i_beta_a = 11 => i_ab_a[1],
            i_d_a = 12 => i_dq_a[0], i_q_a = 13 => i_dq_a[1],
        }
    }
}

record! {
    /// What the sensors delivered at `t_k`.
    pub struct Measured as "Measured" {
        /// Measured phase currents `[a, b, c]` (`c = -a - b`), A.
        pub i_abc_a: [f64; 3] = 1,
        /// Their Clarke transform `[alpha, beta]`, A.
        pub i_ab_a: [f64; 2] = 2,
        /// Measured DC-bus voltage, V.
        pub u_dc_v: f64 = 3,
    }
}

record! {
    /// One observer's estimate at `t_k`, with its errors against the truth.
    pub struct ObserverSample as "ObserverSample" {
        /// Estimated electrical angle, rad.
        pub theta_e_rad: f64 = 1,
        /// Estimated electrical speed, rad/s.
        pub omega_e_rad_s: f64 = 2,
        /// `wrap(theta_hat - theta)`, electrical degrees.
        pub angle_error_deg: f64 = 3,
        /// `omega_hat - omega_e`, electrical rad/s.
        pub speed_error_rad_s: f64 = 4,
        /// Diagonal of the state covariance `P` (`i_a, i_b, w_e, th`): A^2, A^2, (rad/s)^2,
        /// rad^2.
        pub p_diag: [f64; 4] = 5,
        /// Normalized innovation squared of the correction.
        pub nis: f64 = 6,
        /// Whether the observer reports status Tracking (angle standard deviation below the
        /// limit).
        pub tracking: bool = 7,
        /// Tracked flux linkage, Wb (the configured one for an observer without tracking).
        pub psi_f_wb: f64 = 8,
        /// Its standard deviation, Wb (0 when not tracked).
        pub psi_f_sigma_wb: f64 = 9,
        /// Stator resistance in use, ohm (tracked, or the configured one).
        pub rs_ohm: f64 = 10,
        /// Its standard deviation, ohm (0 when not tracked).
        pub rs_sigma_ohm: f64 = 11,
        /// Winding temperature derived from `rs_ohm`, deg C (`NaN` when not known).
        pub winding_temperature_c: f64 = 12,
    }
}

record! {
    /// The controller's side of a sample.
    pub struct ControlRecord as "Control" {
        /// The scenario's mechanical speed reference, rpm.
        pub speed_ref_rpm: f64 = 1,
        /// Duties the controller computed in this period `[a, b, c]`.
        pub duties: [f64; 3] = 2,
        /// The controller's own report.
        pub telemetry: ControllerTelemetry = 3,
    }
}

record! {
    /// What a controller reports about itself, for the log.
    pub struct ControllerTelemetry as "Telemetry" {
        /// Name of the controller's state (`sensored`; foc: `idle`, `align`, `open_loop`,
        /// `handover`, `closed_loop`, `fault`).
        pub state: &'static str = 1,
        /// Angle the controller used for its Park transform, rad.
        pub theta_e_rad: f64 = 2,
        /// Electrical speed the controller used, rad/s.
        pub omega_e_rad_s: f64 = 3,
        /// Measured dq currents in the controller's frame, A.
        pub i_dq_a: [f64; 2] = 4,
        /// dq current references, A.
        pub i_dq_ref_a: [f64; 2] = 5,
        /// dq voltage reference after limiting, V.
        pub u_dq_ref_v: [f64; 2] = 6,
        /// Stationary voltage reference sent to the modulator, V.
        pub u_ab_ref_v: [f64; 2] = 7,
        /// Whether the voltage vector was limited this period.
        pub voltage_limited: bool = 8,
        /// Whether the speed and current loops run on a rotor angle (sensor or a trusted
        /// observer) this period: always for the sensored controller; for foc in the states
        /// `handover` and `closed_loop` (not during alignment or the open-loop I/f ramp).
        pub closed_loop: bool = 9,
        /// The controller's own (slewed) mechanical speed reference, rpm; absent if it has
        /// none or the PWM is off.
        pub speed_ref_rpm: Option<f64> = 10,
        /// The latched fault, if any (e.g. `over_current`, `observer_lost`).
        pub fault: Option<&'static str> = 11,
        /// The estimate of the controller's own observer (for foc: its f32 EKF), if any. The
        /// simulator scores it against the truth like its own observers.
        pub estimate: Option<ControllerEstimate> = 12,
        named {
            i_d_a = 13 => i_dq_a[0], i_q_a = 14 => i_dq_a[1],
            i_d_ref_a = 15 => i_dq_ref_a[0], i_q_ref_a = 16 => i_dq_ref_a[1],
            u_d_ref_v = 17 => u_dq_ref_v[0], u_q_ref_v = 18 => u_dq_ref_v[1],
        }
    }
}

record! {
    /// The rotor estimate of an observer inside the controller (e.g. foc's f32 EKF), after
    /// this period's correction: the estimate of `th(t_k)`, `w_e(t_k)`.
    pub struct ControllerEstimate as "ControllerEstimate" {
        /// Electrical angle, rad.
        pub theta_e_rad: f64 = 1,
        /// Electrical speed, rad/s.
        pub omega_e_rad_s: f64 = 2,
        /// Diagonal of its covariance (`i_a, i_b, w_e, th`).
        pub p_diag: [f64; 4] = 3,
        /// Normalized innovation squared of the last correction.
        pub nis: f64 = 4,
        /// Whether it reports its angle as trusted (status Tracking).
        pub tracking: bool = 5,
        /// Tracked flux linkage, Wb (the configured one for an observer without tracking).
        pub psi_f_wb: f64 = 6,
        /// Its standard deviation, Wb (0 when not tracked).
        pub psi_f_sigma_wb: f64 = 7,
        /// Stator resistance in use, ohm (tracked, or the configured one).
        pub rs_ohm: f64 = 8,
        /// Its standard deviation, ohm (0 when not tracked).
        pub rs_sigma_ohm: f64 = 9,
        /// Winding temperature derived from `rs_ohm`, deg C (`NaN` when not known).
        pub winding_temperature_c: f64 = 10,
    }
}

record! {
    /// The inverter's side of a sample, over `[t_k, t_k+1)`.
    pub struct InverterRecord as "Inverter" {
        /// Whether the bridge switches (`false`: all switches open; the voltages below are
        /// then 0).
        pub pwm_enabled: bool = 1,
        /// Duties applied (the previous period's, with the computation delay on).
        pub duties: [f64; 3] = 2,
        /// Stator voltage actually applied, dead time included, V.
        pub u_ab_v: [f64; 2] = 3,
        /// The ideal voltage of those duties on the bus the controller measured: the
        /// observer's input at sample `k + 1`, V.
        pub u_ab_commanded_v: [f64; 2] = 4,
        /// Bus voltage over the period, V.
        pub u_dc_v: f64 = 5,
        named { u_alpha_v = 6 => u_ab_v[0], u_beta_v = 7 => u_ab_v[1], }
    }
}

impl ObserverSample {
    /// The sample of a controller's own observer ([`ControllerEstimate`]) against the truth.
    pub fn from_controller(e: &ControllerEstimate, truth: &Truth) -> Self {
        Self {
            theta_e_rad: e.theta_e_rad,
            omega_e_rad_s: e.omega_e_rad_s,
            angle_error_deg: wrap_angle(e.theta_e_rad - truth.theta_e_rad).to_degrees(),
            speed_error_rad_s: e.omega_e_rad_s - truth.omega_e_rad_s,
            p_diag: e.p_diag,
            nis: e.nis,
            tracking: e.tracking,
            psi_f_wb: e.psi_f_wb,
            psi_f_sigma_wb: e.psi_f_sigma_wb,
            rs_ohm: e.rs_ohm,
            rs_sigma_ohm: e.rs_sigma_ohm,
            winding_temperature_c: e.winding_temperature_c,
        }
    }
}

/// Bytes of a `pmsm_sim.Period` message besides its text, at most.
pub(crate) const PERIOD_MAX_FIXED: usize = <Sample as Message>::MAX_BODY;

/// Encodes `s` as a `pmsm_sim.Period` message into `buf` (grown as needed, never shrunk) and
/// returns the length.
#[inline]
pub(crate) fn encode_period(buf: &mut Vec<u8>, s: &Sample) -> usize {
    let cap = PERIOD_MAX_FIXED + Message::text_len(s);
    encode_into(buf, cap, |e| s.encode_body(e))
}

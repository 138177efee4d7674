//! Telemetry frames: what the board sends over the UART, and their decoding on the host
//! (`pmsm-sim telemetry FILE --out run.mcap` turns a capture into the project's MCAP log,
//! with the simulator's period record as the one schema).
//!
//! # Frame
//!
//! ```text
//! 0xA5 0x5A | kind (1) | length n (1) | payload (n bytes, little-endian) | CRC-16 (2, LE)
//! ```
//!
//! The CRC ([`crate::crc::crc16`]) covers kind, length and payload. The command replies share
//! the line as ASCII text; they never contain `0xA5`, and a reader resynchronizes on the next
//! sync pair whose CRC checks ([`scan`]).
//!
//! | kind | payload |
//! |---|---|
//! | [`KIND_PERIOD`] | [`PeriodFrame`], [`PERIOD_LEN`] bytes |
//! | [`KIND_META`] | [`MetaFrame`], [`META_LEN`] bytes (sent when telemetry is switched on) |
//!
//! # Period payload
//!
//! Quantities that have a natural range travel as 16-bit fixed point, the rest as `f32`:
//! currents 0.01 A and voltages 0.01 V (`i16`, +-327), duties 1/65535 (`u16`), angles
//! pi/32768 rad (`i16`), temperature 0.01 degC (`i16`); speeds, `psi_f` and `Rs` as `f32`. A
//! value outside the 16-bit range saturates; NaN travels as `i16::MIN` and decodes to NaN.

use crate::crc::crc16;

/// The sync pair that opens every frame.
pub const SYNC: [u8; 2] = [0xA5, 0x5A];
/// Frame kind of a [`PeriodFrame`].
pub const KIND_PERIOD: u8 = 1;
/// Frame kind of a [`MetaFrame`].
pub const KIND_META: u8 = 2;
/// Payload bytes of a [`PeriodFrame`].
pub const PERIOD_LEN: usize = 64;
/// Payload bytes of a [`MetaFrame`].
pub const META_LEN: usize = 12;
/// Bytes around the payload: sync (2), kind, length, CRC (2).
pub const OVERHEAD: usize = 6;
/// The largest frame, bytes.
pub const MAX_FRAME: usize = PERIOD_LEN + OVERHEAD;

/// Bit of [`PeriodFrame::flags`]: the bridge switches.
pub const FLAG_PWM: u8 = 1 << 0;
/// Bit of [`PeriodFrame::flags`]: the observer accepted its step.
pub const FLAG_OBSERVER_OK: u8 = 1 << 1;
/// Bit of [`PeriodFrame::flags`]: the current sample was accepted.
pub const FLAG_SAMPLE_OK: u8 = 1 << 2;
/// Bit of [`PeriodFrame::flags`]: the observer reports status Tracking.
pub const FLAG_TRACKING: u8 = 1 << 3;
/// Bit of [`PeriodFrame::flags`]: the self-commissioning sequence drives the bridge (the
/// controller's fields are then the identifier's frame and voltages).
pub const FLAG_IDENTIFY: u8 = 1 << 4;

/// One PWM period as the board reports it (SI units, electrical angles and speeds).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PeriodFrame {
    /// The controller's tick count (the period index `k`).
    pub tick: u32,
    /// State code ([`crate::state::state_code`]).
    pub state: u8,
    /// Fault code (0: none; [`crate::state::fault_code`]).
    pub fault: u8,
    /// `FLAG_*` bits.
    pub flags: u8,
    /// Phase currents `[a, b, c]` sampled at this period, A.
    pub i_abc_a: [f32; 3],
    /// Bus voltage, V.
    pub u_dc_v: f32,
    /// Duties computed this period `[a, b, c]`.
    pub duties: [f32; 3],
    /// Measured dq currents in the control frame, A.
    pub i_dq_a: [f32; 2],
    /// dq current references, A.
    pub i_dq_ref_a: [f32; 2],
    /// dq voltage after limiting, V.
    pub u_dq_v: [f32; 2],
    /// Realized alpha-beta voltage, V.
    pub u_ab_v: [f32; 2],
    /// Angle of the control frame, rad.
    pub theta_rad: f32,
    /// Speed of the control frame, rad/s.
    pub omega_rad_s: f32,
    /// The controller's (slewed) mechanical speed reference, rad/s.
    pub speed_ref_mech_rad_s: f32,
    /// Observer's angle, rad.
    pub est_theta_rad: f32,
    /// Observer's speed, rad/s.
    pub est_omega_rad_s: f32,
    /// Observer's flux linkage, Wb.
    pub psi_f_wb: f32,
    /// Observer's stator resistance, ohm.
    pub rs_ohm: f32,
    /// Power-stage temperature, degC.
    pub temperature_c: f32,
}

/// Sent when telemetry is switched on: what a reader needs to place the periods in time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MetaFrame {
    /// PWM period, s.
    pub ts_s: f32,
    /// One period frame every this many PWM periods.
    pub every: u16,
    /// Pole pairs of the motor in use.
    pub pole_pairs: u8,
    /// Version of the frame layout ([`LAYOUT_VERSION`]).
    pub layout: u8,
    /// Nominal bus voltage the drive was configured for, V.
    pub u_dc_nominal_v: f32,
}

/// Version of the frame layout; a reader refuses others.
pub const LAYOUT_VERSION: u8 = 1;

/// A decoded frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Frame {
    /// A period.
    Period(PeriodFrame),
    /// The stream's description.
    Meta(MetaFrame),
}

/// What [`scan`] found at the start of a buffer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scan {
    /// A valid frame, and the bytes it took.
    Frame(Frame, usize),
    /// Bytes to drop: no frame starts there (text, noise, a frame whose CRC failed or whose
    /// kind or length is unknown), with what was wrong.
    Skip(usize, SkipReason),
    /// The buffer ends inside a possible frame: read more (at the end of the input, drop it).
    NeedMore,
}

/// Why [`scan`] skipped bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SkipReason {
    /// No sync pair: text or noise.
    NoSync,
    /// A sync pair with an unknown kind, or a length that does not match it.
    BadHeader,
    /// The CRC does not match.
    BadCrc,
    /// A meta frame of another layout version.
    OtherLayout,
}

// Fixed-point scales.
const AMP: f32 = 100.0;
const VOLT: f32 = 100.0;
const RAD: f32 = 32768.0 / core::f32::consts::PI;
const DEG_C: f32 = 100.0;

fn q16(x: f32, scale: f32) -> i16 {
    if x.is_nan() {
        return i16::MIN;
    }
    let v = x * scale;
    // Saturating, and i16::MIN is kept for NaN.
    if v >= 32767.0 {
        32767
    } else if v <= -32767.0 {
        -32767
    } else {
        // Round half away from zero without `f32::round` (a libm call on the MCU).
        (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i16
    }
}

fn dq16(v: i16, scale: f32) -> f32 {
    if v == i16::MIN {
        f32::NAN
    } else {
        f32::from(v) / scale
    }
}

fn duty16(d: f32) -> u16 {
    if d.is_nan() || d <= 0.0 {
        0
    } else if d >= 1.0 {
        u16::MAX
    } else {
        (d * 65535.0 + 0.5) as u16
    }
}

/// A little-endian writer over a fixed buffer (sizes fixed by the layout).
struct Put<'a> {
    out: &'a mut [u8],
    pos: usize,
}

impl Put<'_> {
    fn bytes(&mut self, b: &[u8]) {
        if let Some(dst) = self.out.get_mut(self.pos..self.pos + b.len()) {
            dst.copy_from_slice(b);
        }
        self.pos += b.len();
    }
    fn i16(&mut self, v: i16) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
}

/// A little-endian reader; reads past the end give zeros (the length is checked before).
struct Get<'a> {
    inp: &'a [u8],
    pos: usize,
}

impl Get<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut b = [0u8; N];
        if let Some(src) = self.inp.get(self.pos..self.pos + N) {
            b.copy_from_slice(src);
        }
        self.pos += N;
        b
    }
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn i16(&mut self) -> i16 {
        i16::from_le_bytes(self.take())
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
}

impl PeriodFrame {
    /// The payload.
    pub fn encode_payload(&self, out: &mut [u8; PERIOD_LEN]) {
        let mut p = Put { out, pos: 0 };
        p.bytes(&self.tick.to_le_bytes());
        p.bytes(&[self.state, self.fault, self.flags, 0]);
        for x in self.i_abc_a {
            p.i16(q16(x, AMP));
        }
        p.i16(q16(self.u_dc_v, VOLT));
        for d in self.duties {
            p.bytes(&duty16(d).to_le_bytes());
        }
        for x in self.i_dq_a.into_iter().chain(self.i_dq_ref_a) {
            p.i16(q16(x, AMP));
        }
        for x in self.u_dq_v.into_iter().chain(self.u_ab_v) {
            p.i16(q16(x, VOLT));
        }
        p.i16(q16(self.theta_rad, RAD));
        p.i16(q16(self.est_theta_rad, RAD));
        p.f32(self.omega_rad_s);
        p.f32(self.speed_ref_mech_rad_s);
        p.f32(self.est_omega_rad_s);
        p.f32(self.psi_f_wb);
        p.f32(self.rs_ohm);
        p.i16(q16(self.temperature_c, DEG_C));
        debug_assert_eq!(p.pos, PERIOD_LEN);
    }

    /// Decodes a payload of [`PERIOD_LEN`] bytes.
    pub fn decode_payload(b: &[u8]) -> Self {
        let mut g = Get { inp: b, pos: 0 };
        let tick = g.u32();
        let (state, fault, flags) = (g.u8(), g.u8(), g.u8());
        let _ = g.u8();
        let i_abc_a = [0; 3].map(|_: i32| dq16(g.i16(), AMP));
        let u_dc_v = dq16(g.i16(), VOLT);
        let duties = [0; 3].map(|_: i32| f32::from(g.u16()) / 65535.0);
        let i_dq_a = [0; 2].map(|_: i32| dq16(g.i16(), AMP));
        let i_dq_ref_a = [0; 2].map(|_: i32| dq16(g.i16(), AMP));
        let u_dq_v = [0; 2].map(|_: i32| dq16(g.i16(), VOLT));
        let u_ab_v = [0; 2].map(|_: i32| dq16(g.i16(), VOLT));
        let theta_rad = dq16(g.i16(), RAD);
        let est_theta_rad = dq16(g.i16(), RAD);
        Self {
            tick,
            state,
            fault,
            flags,
            i_abc_a,
            u_dc_v,
            duties,
            i_dq_a,
            i_dq_ref_a,
            u_dq_v,
            u_ab_v,
            theta_rad,
            omega_rad_s: g.f32(),
            speed_ref_mech_rad_s: g.f32(),
            est_theta_rad,
            est_omega_rad_s: g.f32(),
            psi_f_wb: g.f32(),
            rs_ohm: g.f32(),
            temperature_c: dq16(g.i16(), DEG_C),
        }
    }

    /// The whole frame into `out`; returns its length.
    pub fn encode(&self, out: &mut [u8; MAX_FRAME]) -> usize {
        let mut payload = [0u8; PERIOD_LEN];
        self.encode_payload(&mut payload);
        wrap(KIND_PERIOD, &payload, out)
    }
}

impl MetaFrame {
    /// The whole frame into `out`; returns its length.
    pub fn encode(&self, out: &mut [u8; MAX_FRAME]) -> usize {
        let mut payload = [0u8; META_LEN];
        let mut p = Put {
            out: &mut payload,
            pos: 0,
        };
        p.f32(self.ts_s);
        p.bytes(&self.every.to_le_bytes());
        p.bytes(&[self.pole_pairs, self.layout]);
        p.f32(self.u_dc_nominal_v);
        wrap(KIND_META, &payload, out)
    }

    fn decode_payload(b: &[u8]) -> Self {
        let mut g = Get { inp: b, pos: 0 };
        Self {
            ts_s: g.f32(),
            every: g.u16(),
            pole_pairs: g.u8(),
            layout: g.u8(),
            u_dc_nominal_v: g.f32(),
        }
    }
}

/// Frames `payload` of `kind`; returns the frame's length.
fn wrap(kind: u8, payload: &[u8], out: &mut [u8; MAX_FRAME]) -> usize {
    let n = payload.len().min(MAX_FRAME - OVERHEAD);
    out[..2].copy_from_slice(&SYNC);
    out[2] = kind;
    out[3] = n as u8;
    out[4..4 + n].copy_from_slice(&payload[..n]);
    let crc = crc16(&out[2..4 + n]);
    out[4 + n..6 + n].copy_from_slice(&crc.to_le_bytes());
    n + OVERHEAD
}

/// The payload length of a frame kind.
fn payload_len(kind: u8) -> Option<usize> {
    match kind {
        KIND_PERIOD => Some(PERIOD_LEN),
        KIND_META => Some(META_LEN),
        _ => None,
    }
}

/// Looks for a frame at the start of `buf` (module docs). Never panics, whatever the bytes.
pub fn scan(buf: &[u8]) -> Scan {
    let Some(first) = buf.first() else {
        return Scan::NeedMore;
    };
    if *first != SYNC[0] {
        let n = buf.iter().position(|&b| b == SYNC[0]).unwrap_or(buf.len());
        return Scan::Skip(n, SkipReason::NoSync);
    }
    if buf.len() < 4 {
        return Scan::NeedMore;
    }
    if buf[1] != SYNC[1] {
        return Scan::Skip(1, SkipReason::NoSync);
    }
    let (kind, len) = (buf[2], usize::from(buf[3]));
    if payload_len(kind) != Some(len) {
        return Scan::Skip(1, SkipReason::BadHeader);
    }
    let total = len + OVERHEAD;
    if buf.len() < total {
        return Scan::NeedMore;
    }
    let crc = u16::from_le_bytes([buf[4 + len], buf[5 + len]]);
    if crc16(&buf[2..4 + len]) != crc {
        return Scan::Skip(1, SkipReason::BadCrc);
    }
    let payload = &buf[4..4 + len];
    let frame = if kind == KIND_PERIOD {
        Frame::Period(PeriodFrame::decode_payload(payload))
    } else {
        let m = MetaFrame::decode_payload(payload);
        if m.layout != LAYOUT_VERSION {
            return Scan::Skip(total, SkipReason::OtherLayout);
        }
        Frame::Meta(m)
    };
    Scan::Frame(frame, total)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> PeriodFrame {
        PeriodFrame {
            tick: 123_456,
            state: 4,
            fault: 0,
            flags: FLAG_PWM | FLAG_SAMPLE_OK | FLAG_TRACKING,
            i_abc_a: [1.23, -0.5, -0.73],
            u_dc_v: 24.07,
            duties: [0.5, 0.25, 0.999],
            i_dq_a: [0.01, 2.5],
            i_dq_ref_a: [0.0, 2.6],
            u_dq_v: [-0.4, 3.2],
            u_ab_v: [1.0, -3.1],
            theta_rad: -3.0,
            omega_rad_s: 1234.5,
            speed_ref_mech_rad_s: 300.0,
            est_theta_rad: 3.1,
            est_omega_rad_s: 1230.0,
            psi_f_wb: 0.0051,
            rs_ohm: 0.12,
            temperature_c: 41.5,
        }
    }

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn period_round_trip_within_the_quantization() {
        let f = sample();
        let mut out = [0u8; MAX_FRAME];
        let n = f.encode(&mut out);
        assert_eq!(n, PERIOD_LEN + OVERHEAD);
        let Scan::Frame(Frame::Period(g), used) = scan(&out[..n]) else {
            panic!("not decoded: {:?}", scan(&out[..n]));
        };
        assert_eq!(used, n);
        assert_eq!((g.tick, g.state, g.fault, g.flags), (f.tick, 4, 0, f.flags));
        for (a, b) in g.i_abc_a.iter().zip(f.i_abc_a) {
            assert!(close(*a, b, 0.005));
        }
        assert!(close(g.u_dc_v, f.u_dc_v, 0.005));
        for (a, b) in g.duties.iter().zip(f.duties) {
            assert!(close(*a, b, 1.0 / 65535.0));
        }
        assert!(close(g.theta_rad, f.theta_rad, 1e-4));
        assert!(close(g.est_theta_rad, f.est_theta_rad, 1e-4));
        assert_eq!(g.omega_rad_s, f.omega_rad_s);
        assert_eq!(g.psi_f_wb, f.psi_f_wb);
        assert!(close(g.temperature_c, 41.5, 0.005));
    }

    #[test]
    fn nan_and_out_of_range_values() {
        let mut f = sample();
        f.i_abc_a = [f32::NAN, 1e6, -1e6];
        f.duties = [f32::NAN, -0.2, 7.0];
        let mut out = [0u8; MAX_FRAME];
        let n = f.encode(&mut out);
        let Scan::Frame(Frame::Period(g), _) = scan(&out[..n]) else {
            panic!("not decoded");
        };
        assert!(g.i_abc_a[0].is_nan());
        assert!(close(g.i_abc_a[1], 327.67, 1e-3));
        assert!(close(g.i_abc_a[2], -327.67, 1e-3));
        assert_eq!(g.duties, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn meta_round_trip_and_other_layouts_refused() {
        let m = MetaFrame {
            ts_s: 50e-6,
            every: 20,
            pole_pairs: 7,
            layout: LAYOUT_VERSION,
            u_dc_nominal_v: 24.0,
        };
        let mut out = [0u8; MAX_FRAME];
        let n = m.encode(&mut out);
        assert_eq!(scan(&out[..n]), Scan::Frame(Frame::Meta(m), n));
        let other = MetaFrame { layout: 9, ..m };
        let n = other.encode(&mut out);
        assert_eq!(scan(&out[..n]), Scan::Skip(n, SkipReason::OtherLayout));
    }

    #[test]
    fn text_noise_and_corruption_are_skipped() {
        let mut out = [0u8; MAX_FRAME];
        let n = sample().encode(&mut out);
        let mut stream = b"ok\n".to_vec();
        stream.extend_from_slice(&out[..n]);
        let mut bad = out;
        bad[10] ^= 1;
        stream.extend_from_slice(&bad[..n]);
        stream.extend_from_slice(b"err unknown command\n");
        stream.extend_from_slice(&out[..n]);
        stream.extend_from_slice(&out[..n / 2]);
        let (mut frames, mut crc_skips, mut pos) = (0, 0, 0);
        loop {
            match scan(&stream[pos..]) {
                Scan::Frame(_, k) => {
                    frames += 1;
                    pos += k;
                }
                Scan::Skip(k, r) => {
                    crc_skips += usize::from(r == SkipReason::BadCrc);
                    pos += k;
                }
                Scan::NeedMore => break,
            }
        }
        assert_eq!(frames, 2);
        assert_eq!(crc_skips, 1);
        assert!(stream.len() - pos < n);
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut buf = [0u8; 512];
        for _ in 0..200 {
            for b in buf.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = if x.is_multiple_of(7) { 0xA5 } else { x as u8 };
            }
            let mut pos = 0;
            while let Scan::Frame(_, k) | Scan::Skip(k, _) = scan(&buf[pos..]) {
                assert!(k > 0);
                pos += k;
            }
        }
    }
}

//! The identified motor as a flash record: 48 bytes in the last 2 KiB page of the flash,
//! written after a successful `identify`, read at reset. The drive uses it from its first
//! start; without a valid record `start` identifies the motor first (feature `identify`) or
//! refuses (without it).
//!
//! # Layout (little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `FOCM` |
//! | 4 | 2 | layout version ([`VERSION`]) |
//! | 6 | 2 | length ([`RECORD_LEN`]) |
//! | 8 | 4 | `Rs`, ohm (`f32`) |
//! | 12 | 4 | `Ld`, H |
//! | 16 | 4 | `Lq`, H |
//! | 20 | 4 | `psi_f`, Wb |
//! | 24 | 4 | inertia, kg m^2 (NaN: not measured) |
//! | 28 | 4 | inverter voltage error at the test current, V |
//! | 32 | 4 | test current of the identification, A |
//! | 36 | 1 | pole pairs |
//! | 37 | 7 | zero |
//! | 44 | 4 | CRC-32 of bytes 0..44 ([`crate::crc::crc32`]) |
//!
//! The length is a multiple of 8: the STM32G4 programs its flash by double words. An erased
//! page reads `0xFF` and decodes as [`RecordError::Erased`].

use crate::crc::crc32;
use foc::ekf_core::MotorParams;

/// Record bytes.
pub const RECORD_LEN: usize = 48;
/// Layout version.
pub const VERSION: u16 = 1;
const MAGIC: [u8; 4] = *b"FOCM";

/// The identified motor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorRecord {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: f32,
    /// d-axis inductance, H.
    pub ld_h: f32,
    /// q-axis inductance, H.
    pub lq_h: f32,
    /// Flux linkage, Wb.
    pub psi_f_wb: f32,
    /// Inertia, kg m^2 (NaN: not measured).
    pub j_kg_m2: f32,
    /// Inverter voltage error at the test current, V.
    pub inverter_voltage_error_v: f32,
    /// Test current the identification used, A.
    pub test_current_a: f32,
    /// Pole pairs.
    pub pole_pairs: u8,
}

/// Why a record was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// The page is erased (no record written yet).
    Erased,
    /// Not a record (wrong magic or length).
    NotARecord,
    /// A record of another layout version.
    OtherVersion(u16),
    /// The check sum does not match (a torn write, a flipped bit).
    BadCrc {
        /// CRC stored in the record.
        stored: u32,
        /// CRC of the bytes read.
        computed: u32,
    },
    /// A value is not physical (named by its field).
    Invalid(&'static str),
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RecordError::Erased => f.write_str("no motor record (erased flash)"),
            RecordError::NotARecord => f.write_str("not a motor record"),
            RecordError::OtherVersion(v) => write!(f, "motor record of layout version {v}"),
            RecordError::BadCrc { stored, computed } => write!(
                f,
                "motor record CRC mismatch (stored {stored:#010x}, computed {computed:#010x})"
            ),
            RecordError::Invalid(field) => write!(f, "motor record field {field} is not valid"),
        }
    }
}

impl core::error::Error for RecordError {}

impl RecordError {
    /// A short name for the status line.
    pub fn as_str(self) -> &'static str {
        match self {
            RecordError::Erased => "none",
            RecordError::NotARecord => "not_a_record",
            RecordError::OtherVersion(_) => "other_version",
            RecordError::BadCrc { .. } => "bad_crc",
            RecordError::Invalid(_) => "invalid",
        }
    }
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    let mut x = [0u8; 4];
    if let Some(s) = b.get(at..at + 4) {
        x.copy_from_slice(s);
    }
    f32::from_le_bytes(x)
}

impl MotorRecord {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut b = [0u8; RECORD_LEN];
        b[0..4].copy_from_slice(&MAGIC);
        b[4..6].copy_from_slice(&VERSION.to_le_bytes());
        b[6..8].copy_from_slice(&(RECORD_LEN as u16).to_le_bytes());
        let vals = [
            self.rs_ohm,
            self.ld_h,
            self.lq_h,
            self.psi_f_wb,
            self.j_kg_m2,
            self.inverter_voltage_error_v,
            self.test_current_a,
        ];
        for (i, v) in vals.iter().enumerate() {
            b[8 + 4 * i..12 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        b[36] = self.pole_pairs;
        let crc = crc32(&b[..44]);
        b[44..48].copy_from_slice(&crc.to_le_bytes());
        b
    }

    /// Reads a record; checks magic, version, length, CRC and that the values are physical
    /// ([`MotorRecord::validate`]). Never panics: a short slice is [`RecordError::NotARecord`].
    pub fn decode(b: &[u8]) -> Result<Self, RecordError> {
        if b.len() < RECORD_LEN {
            return Err(RecordError::NotARecord);
        }
        let b = &b[..RECORD_LEN];
        if b.iter().all(|&x| x == 0xFF) {
            return Err(RecordError::Erased);
        }
        if b[0..4] != MAGIC || u16::from_le_bytes([b[6], b[7]]) != RECORD_LEN as u16 {
            return Err(RecordError::NotARecord);
        }
        let version = u16::from_le_bytes([b[4], b[5]]);
        if version != VERSION {
            return Err(RecordError::OtherVersion(version));
        }
        let stored = u32::from_le_bytes([b[44], b[45], b[46], b[47]]);
        let computed = crc32(&b[..44]);
        if stored != computed {
            return Err(RecordError::BadCrc { stored, computed });
        }
        let r = Self {
            rs_ohm: f32_at(b, 8),
            ld_h: f32_at(b, 12),
            lq_h: f32_at(b, 16),
            psi_f_wb: f32_at(b, 20),
            j_kg_m2: f32_at(b, 24),
            inverter_voltage_error_v: f32_at(b, 28),
            test_current_a: f32_at(b, 32),
            pole_pairs: b[36],
        };
        r.validate()?;
        Ok(r)
    }

    /// The values are finite and in physical ranges (`Rs` 1 mOhm..1 kOhm, `L` 1 uH..1 H,
    /// `psi_f` 10 uWb..10 Wb, 1..64 pole pairs; the inertia positive or NaN).
    pub fn validate(&self) -> Result<(), RecordError> {
        let within = |x: f32, lo: f32, hi: f32| x.is_finite() && x >= lo && x <= hi;
        if !within(self.rs_ohm, 1e-3, 1e3) {
            return Err(RecordError::Invalid("rs_ohm"));
        }
        if !within(self.ld_h, 1e-6, 1.0) {
            return Err(RecordError::Invalid("ld_h"));
        }
        if !within(self.lq_h, 1e-6, 1.0) {
            return Err(RecordError::Invalid("lq_h"));
        }
        if !within(self.psi_f_wb, 1e-5, 10.0) {
            return Err(RecordError::Invalid("psi_f_wb"));
        }
        if !(self.j_kg_m2.is_nan() || within(self.j_kg_m2, 1e-9, 10.0)) {
            return Err(RecordError::Invalid("j_kg_m2"));
        }
        if !self.inverter_voltage_error_v.is_finite() {
            return Err(RecordError::Invalid("inverter_voltage_error_v"));
        }
        if !within(self.test_current_a, 0.0, 1e3) {
            return Err(RecordError::Invalid("test_current_a"));
        }
        if !(1..=64).contains(&self.pole_pairs) {
            return Err(RecordError::Invalid("pole_pairs"));
        }
        Ok(())
    }

    /// The motor parameters the controller and its observer use.
    pub fn motor_params(&self) -> MotorParams<f32> {
        MotorParams {
            rs_ohm: self.rs_ohm,
            ld_h: self.ld_h,
            lq_h: self.lq_h,
            psi_f_wb: self.psi_f_wb,
            pole_pairs: u32::from(self.pole_pairs),
        }
    }

    /// The record of an identification (`None` without a measured `psi_f`: the sequence
    /// ran without its spin). `Ld`, `Lq` as [`foc::Identified::motor_params`] gives them.
    #[cfg(feature = "identify")]
    pub fn from_identified(
        id: &foc::Identified,
        pole_pairs: u8,
        test_current_a: f32,
    ) -> Option<Self> {
        let m = id.motor_params(u32::from(pole_pairs))?;
        Some(Self {
            rs_ohm: m.rs_ohm,
            ld_h: m.ld_h,
            lq_h: m.lq_h,
            psi_f_wb: m.psi_f_wb,
            j_kg_m2: id.j_kg_m2.unwrap_or(f32::NAN),
            inverter_voltage_error_v: id.inverter_voltage_error_v,
            test_current_a,
            pole_pairs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec() -> MotorRecord {
        MotorRecord {
            rs_ohm: 0.11,
            ld_h: 25e-6,
            lq_h: 27e-6,
            psi_f_wb: 0.0042,
            j_kg_m2: f32::NAN,
            inverter_voltage_error_v: 0.31,
            test_current_a: 2.0,
            pole_pairs: 7,
        }
    }

    #[test]
    fn round_trip_bit_for_bit() {
        let b = rec().encode();
        let r = MotorRecord::decode(&b).unwrap();
        assert_eq!(r.encode(), b);
        assert!(r.j_kg_m2.is_nan());
        assert_eq!(r.motor_params().pole_pairs, 7);
        assert_eq!(b.len() % 8, 0);
    }

    #[test]
    fn every_bad_record_is_named() {
        assert_eq!(
            MotorRecord::decode(&[0xFF; RECORD_LEN]),
            Err(RecordError::Erased)
        );
        assert_eq!(
            MotorRecord::decode(&[0u8; 10]),
            Err(RecordError::NotARecord)
        );
        let good = rec().encode();
        let mut b = good;
        b[0] = b'X';
        assert_eq!(MotorRecord::decode(&b), Err(RecordError::NotARecord));
        let mut b = good;
        b[4] = 2;
        assert_eq!(MotorRecord::decode(&b), Err(RecordError::OtherVersion(2)));
        for byte in 8..44 {
            let mut b = good;
            b[byte] ^= 0x04;
            assert!(
                matches!(MotorRecord::decode(&b), Err(RecordError::BadCrc { .. })),
                "flip in byte {byte} not caught"
            );
        }
        let r = MotorRecord {
            pole_pairs: 0,
            ..rec()
        };
        assert_eq!(
            MotorRecord::decode(&r.encode()),
            Err(RecordError::Invalid("pole_pairs"))
        );
        let r = MotorRecord {
            rs_ohm: f32::NAN,
            ..rec()
        };
        assert_eq!(
            MotorRecord::decode(&r.encode()),
            Err(RecordError::Invalid("rs_ohm"))
        );
    }

    #[cfg(feature = "identify")]
    #[test]
    fn from_an_identification() {
        let id = foc::Identified {
            rs_ohm: 0.2,
            ld_h: 1e-4,
            lq_h: 1.01e-4,
            psi_f_wb: Some(0.01),
            inverter_voltage_error_v: 0.4,
            j_kg_m2: Some(2e-5),
            current_offsets_a: [0.0; 2],
            step_ticks: [0; 8],
            ticks: 0,
        };
        let r = MotorRecord::from_identified(&id, 7, 2.0).unwrap();
        let back = MotorRecord::decode(&r.encode()).unwrap();
        assert_eq!(back, r);
        // A surface motor: both inductances the mean.
        assert_eq!(back.ld_h, back.lq_h);
        let no_spin = foc::Identified {
            psi_f_wb: None,
            ..id
        };
        assert!(MotorRecord::from_identified(&no_spin, 7, 2.0).is_none());
    }
}

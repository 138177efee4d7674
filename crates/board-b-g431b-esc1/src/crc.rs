//! Check sums: CRC-16/CCITT-FALSE for telemetry frames, CRC-32 (IEEE 802.3, the zlib one)
//! for the flash record. Bitwise (no tables): a few dozen bytes of code, and the frames are
//! short.

/// CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final
/// XOR. Check value of `b"123456789"`: 0x29B1.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, initial value and final XOR
/// 0xFFFFFFFF). Check value of `b"123456789"`: 0xCBF43926.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc: u32 = 0xFFFF_FFFF;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_check_values() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc16(b""), 0xFFFF);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn a_flipped_bit_changes_both() {
        let mut d = *b"field-oriented control";
        let (a, b) = (crc16(&d), crc32(&d));
        d[5] ^= 0x10;
        assert_ne!(crc16(&d), a);
        assert_ne!(crc32(&d), b);
    }
}

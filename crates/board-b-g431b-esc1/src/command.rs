//! The command interface: one ASCII line per command, on the UART (the ST-LINK's virtual COM
//! port), answered by one line (`ok ...` or `err <reason>`).
//!
//! | line | what |
//! |---|---|
//! | `start` | checks (bus, offsets), then starts the drive (align or I/f, then closed loop) |
//! | `stop` | controlled stop: the speed ramps down, then the PWM goes off |
//! | `off` | PWM off at once (the motor coasts) |
//! | `clear` | clears a latched fault (the board and foc's) |
//! | `speed <rpm>` | mechanical speed reference, rpm; the sign is the direction |
//! | `identify [pole_pairs]` | self-commissioning (PWM on, the rotor turns) for a motor of that many pole pairs (default 7), then the motor record is written to flash |
//! | `forget` | erases the motor record (the next start uses the built-in motor) |
//! | `telemetry <n>` | one telemetry frame every `n` PWM periods (`0`: off) |
//! | `status` | one line: state, fault, bus voltage, motor source |
//!
//! Words are case-sensitive, separated by spaces; a line ends with `\n` (a `\r` before it is
//! ignored) and holds at most [`MAX_LINE`] bytes. Bad input never panics: it gives a
//! [`ParseError`] whose [`ParseError::as_str`] is the reply.
//!
//! foc's controller has a speed loop only: there is no torque command (a torque mode would
//! belong in `foc`, not in the board crate).

/// Longest line, bytes (without the line end).
pub const MAX_LINE: usize = 48;

/// Largest speed reference accepted, rpm (foc clamps it further to the configured maximum).
pub const MAX_SPEED_RPM: f32 = 100_000.0;

/// Largest telemetry divider.
pub const MAX_TELEMETRY_EVERY: u32 = 60_000;

/// A command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// Start the drive.
    Start,
    /// Controlled stop.
    Stop,
    /// PWM off at once.
    Off,
    /// Clear a latched fault.
    Clear,
    /// Mechanical speed reference, rpm.
    Speed {
        /// Signed mechanical speed, rpm.
        rpm: f32,
    },
    /// Run the self-commissioning sequence and store its result.
    Identify {
        /// Pole pairs of the motor (the identification cannot measure them), 1..=64.
        pole_pairs: u8,
    },
    /// Erase the stored motor record.
    Forget,
    /// Telemetry rate.
    Telemetry {
        /// One frame every this many PWM periods; 0: off.
        every: u16,
    },
    /// One status line.
    Status,
}

/// Why a line was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// The line is empty.
    Empty,
    /// The line is longer than [`MAX_LINE`] bytes.
    TooLong,
    /// The first word is not a command.
    Unknown,
    /// The command needs a value.
    MissingValue,
    /// The value is not a decimal number.
    BadNumber,
    /// The value is out of range.
    OutOfRange,
    /// More words than the command takes.
    Extra,
}

impl ParseError {
    /// The reply line's text.
    pub fn as_str(self) -> &'static str {
        match self {
            ParseError::Empty => "empty line",
            ParseError::TooLong => "line too long",
            ParseError::Unknown => {
                "unknown command (start stop off clear speed identify forget telemetry status)"
            }
            ParseError::MissingValue => "missing value",
            ParseError::BadNumber => "value is not a decimal number",
            ParseError::OutOfRange => "value out of range",
            ParseError::Extra => "unexpected extra words",
        }
    }
}

impl core::fmt::Display for ParseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl core::error::Error for ParseError {}

/// Parses one line (without its line end).
pub fn parse(line: &[u8]) -> Result<Command, ParseError> {
    if line.len() > MAX_LINE {
        return Err(ParseError::TooLong);
    }
    let mut words = line
        .split(|&b| b == b' ' || b == b'\t')
        .filter(|w| !w.is_empty());
    let Some(word) = words.next() else {
        return Err(ParseError::Empty);
    };
    let cmd = match word {
        b"start" => Command::Start,
        b"stop" => Command::Stop,
        b"off" => Command::Off,
        b"clear" => Command::Clear,
        b"identify" => match words.next() {
            None => Command::Identify {
                pole_pairs: crate::state::DEFAULT_POLE_PAIRS,
            },
            Some(w) => {
                let v = parse_decimal(w)?;
                if !(1.0..=64.0).contains(&v) || v != (v as u32) as f32 {
                    return Err(ParseError::OutOfRange);
                }
                Command::Identify {
                    pole_pairs: v as u8,
                }
            }
        },
        b"forget" => Command::Forget,
        b"status" => Command::Status,
        b"speed" => {
            let v = parse_decimal(words.next().ok_or(ParseError::MissingValue)?)?;
            if v.abs() > MAX_SPEED_RPM {
                return Err(ParseError::OutOfRange);
            }
            Command::Speed { rpm: v }
        }
        b"telemetry" => {
            let v = parse_decimal(words.next().ok_or(ParseError::MissingValue)?)?;
            if !(0.0..=MAX_TELEMETRY_EVERY as f32).contains(&v) || v != (v as u32) as f32 {
                return Err(ParseError::OutOfRange);
            }
            Command::Telemetry { every: v as u16 }
        }
        _ => return Err(ParseError::Unknown),
    };
    if words.next().is_some() {
        return Err(ParseError::Extra);
    }
    Ok(cmd)
}

/// A decimal number: optional sign, digits, optional fraction (`-1500`, `+12.5`, `.5`); at
/// most 9 significant digits. No exponent, no `inf`/`nan`. (`str::parse::<f32>` would pull
/// in several KiB of float parsing.)
pub fn parse_decimal(s: &[u8]) -> Result<f32, ParseError> {
    let (neg, digits) = match s.first() {
        Some(b'-') => (true, &s[1..]),
        Some(b'+') => (false, &s[1..]),
        _ => (false, s),
    };
    let mut mantissa: u32 = 0;
    let mut n_digits = 0u32;
    let mut frac_digits = 0i32;
    let mut seen_point = false;
    for &b in digits {
        match b {
            b'0'..=b'9' => {
                if n_digits >= 9 {
                    return Err(ParseError::OutOfRange);
                }
                mantissa = mantissa * 10 + u32::from(b - b'0');
                if mantissa != 0 {
                    n_digits += 1;
                }
                if seen_point {
                    frac_digits += 1;
                }
            }
            b'.' if !seen_point => seen_point = true,
            _ => return Err(ParseError::BadNumber),
        }
    }
    let any_digit = digits.iter().any(u8::is_ascii_digit);
    if !any_digit {
        return Err(ParseError::BadNumber);
    }
    let mut v = mantissa as f32;
    for _ in 0..frac_digits {
        v /= 10.0;
    }
    Ok(if neg { -v } else { v })
}

/// Collects received bytes into lines and parses each.
#[derive(Clone, Debug)]
pub struct LineBuffer {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
        }
    }

    /// Takes one received byte; at the end of a line returns the parsed command (an empty
    /// line returns `None`). A line longer than [`MAX_LINE`] is dropped whole and reported
    /// as [`ParseError::TooLong`] at its end.
    pub fn push(&mut self, b: u8) -> Option<Result<Command, ParseError>> {
        match b {
            b'\n' => {
                let r = if self.overflow {
                    Some(Err(ParseError::TooLong))
                } else if self.buf[..self.len].iter().all(|&c| c == b' ') {
                    None
                } else {
                    Some(parse(&self.buf[..self.len]))
                };
                self.len = 0;
                self.overflow = false;
                r
            }
            b'\r' => None,
            _ => {
                if self.len < MAX_LINE {
                    self.buf[self.len] = b;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(lb: &mut LineBuffer, s: &[u8]) -> Vec<Result<Command, ParseError>> {
        s.iter().filter_map(|&b| lb.push(b)).collect()
    }

    #[test]
    fn every_command_parses() {
        assert_eq!(parse(b"start"), Ok(Command::Start));
        assert_eq!(parse(b"stop"), Ok(Command::Stop));
        assert_eq!(parse(b"off"), Ok(Command::Off));
        assert_eq!(parse(b"clear"), Ok(Command::Clear));
        assert_eq!(parse(b"identify"), Ok(Command::Identify { pole_pairs: 7 }));
        assert_eq!(
            parse(b"identify 4"),
            Ok(Command::Identify { pole_pairs: 4 })
        );
        assert_eq!(parse(b"identify 0"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"identify 2.5"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"forget"), Ok(Command::Forget));
        assert_eq!(parse(b"status"), Ok(Command::Status));
        assert_eq!(parse(b"speed -1500"), Ok(Command::Speed { rpm: -1500.0 }));
        assert_eq!(parse(b"  speed\t+12.5 "), Ok(Command::Speed { rpm: 12.5 }));
        assert_eq!(parse(b"telemetry 20"), Ok(Command::Telemetry { every: 20 }));
        assert_eq!(parse(b"telemetry 0"), Ok(Command::Telemetry { every: 0 }));
    }

    #[test]
    fn bad_lines_are_named() {
        assert_eq!(parse(b""), Err(ParseError::Empty));
        assert_eq!(parse(b"   "), Err(ParseError::Empty));
        assert_eq!(parse(b"spin"), Err(ParseError::Unknown));
        assert_eq!(parse(b"START"), Err(ParseError::Unknown));
        assert_eq!(parse(b"speed"), Err(ParseError::MissingValue));
        assert_eq!(parse(b"speed 1e3"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"speed 1.2.3"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"speed -"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"speed nan"), Err(ParseError::BadNumber));
        assert_eq!(parse(b"speed 200000"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"speed 1234567890"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"telemetry 1.5"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"telemetry -1"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"telemetry 70000"), Err(ParseError::OutOfRange));
        assert_eq!(parse(b"start now"), Err(ParseError::Extra));
        assert_eq!(parse(&[b'x'; MAX_LINE + 1]), Err(ParseError::TooLong));
        assert!(ParseError::Unknown.as_str().contains("speed"));
    }

    #[test]
    fn decimals_are_exact_enough() {
        for (s, v) in [
            (&b"0"[..], 0.0),
            (b"007", 7.0),
            (b".5", 0.5),
            (b"3000.25", 3000.25),
            (b"-0.001", -0.001),
        ] {
            let got = parse_decimal(s).unwrap();
            assert!((got - v).abs() <= 1e-6 * v.abs().max(1.0), "{s:?}: {got}");
        }
    }

    #[test]
    fn lines_are_split_and_overflow_is_reported_once() {
        let mut lb = LineBuffer::new();
        let got = feed(&mut lb, b"start\r\n\nspeed 100\nbogus\n");
        assert_eq!(
            got,
            vec![
                Ok(Command::Start),
                Ok(Command::Speed { rpm: 100.0 }),
                Err(ParseError::Unknown)
            ]
        );
        let mut long = vec![b'a'; 3 * MAX_LINE];
        long.push(b'\n');
        long.extend_from_slice(b"stop\n");
        assert_eq!(
            feed(&mut lb, &long),
            vec![Err(ParseError::TooLong), Ok(Command::Stop)]
        );
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        let mut lb = LineBuffer::new();
        let mut x: u32 = 12345;
        for _ in 0..20_000 {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let _ = lb.push((x >> 24) as u8);
        }
    }
}

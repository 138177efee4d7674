//! Instructions retired per call, counted with the SysTick timer under QEMU's `-icount`.
//!
//! # How the count is made
//!
//! QEMU does not model cycles, and its DWT cycle counter reads 0 on `mps2-an386`. With
//! `-icount shift=N` every retired instruction advances virtual time by exactly `2^N` ns, and
//! the SysTick, clocked from the core clock (25 MHz on this board, 40 ns per tick), counts that
//! virtual time. So `ticks = instructions * 2^N / 40`: 25.6 ticks per instruction for `N = 10`,
//! the shift `scripts/qemu-firmware.sh` uses. The firmware does not trust that arithmetic: it
//! measures the scale on a loop of known length written in assembly (`subs`, `bne`: exactly two
//! instructions per iteration) and checks that the count is linear in the length.
//!
//! A measured call is `count(&mut || ...)`: read SysTick, call the closure through a `dyn`
//! pointer (an opaque call the compiler cannot move code across), read SysTick again. The
//! fixed cost of that frame (the two reads, the call and return) is measured with an empty
//! closure and subtracted; what remains is the closure's body, i.e. the measured function
//! plus loading its arguments from the closure's captures and storing its result (a handful
//! of instructions).
//!
//! The 24-bit counter wraps every `2^24` ticks (655 360 instructions at `N = 10`); a single
//! call must stay below that, which the loops here do by far.

use core::arch::asm;

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_semihosting::hprintln;

/// Most calls one [`Tally`] records.
pub const MAX_CALLS: usize = 2000;

/// SysTick's 24-bit counter mask (it counts down from `RELOAD` to 0, then reloads).
const COUNTER_MASK: u32 = 0x00FF_FFFF;

/// Iterations of the calibration loops (`2 n` instructions each).
const CAL_SHORT: u32 = 1000;
const CAL_MID: u32 = 2000;
const CAL_LONG: u32 = 3000;
/// Instructions between the short and the long calibration loop.
const CAL_INSTRUCTIONS: u32 = 2 * (CAL_LONG - CAL_SHORT);

/// Why the counter cannot be trusted.
#[derive(Clone, Copy, Debug)]
pub enum CalibrationError {
    /// The loop count is not linear in its length: QEMU was run without `-icount shift=N`
    /// (or the shift is too small to resolve single instructions).
    NotLinear {
        /// Ticks for the first 2000 extra instructions.
        first: u32,
        /// Ticks for the next 2000.
        second: u32,
    },
}

/// Converts SysTick ticks to instructions; built by [`Clock::start`].
pub struct Clock {
    /// Ticks counted over [`CAL_INSTRUCTIONS`] instructions.
    cal_ticks: u32,
    /// Ticks of the measurement frame alone (empty closure).
    overhead_ticks: u32,
}

/// Ticks between two reads of the SysTick around one call of `f`.
#[inline(never)]
fn ticks_of(f: &mut dyn FnMut()) -> u32 {
    let t0 = SYST::get_current();
    f();
    let t1 = SYST::get_current();
    t0.wrapping_sub(t1) & COUNTER_MASK
}

/// Exactly `2 n` instructions (`n >= 1`): `subs` and `bne`, `n` times.
#[inline(never)]
fn spin(n: u32) {
    // SAFETY: a register-only loop; it touches no memory and no stack, and `n >= 1`.
    unsafe {
        asm!(
            "2:",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) n => _,
            options(nomem, nostack),
        );
    }
}

impl Clock {
    /// Starts the SysTick on the core clock, free-running over its full 24-bit range, and
    /// calibrates ticks per instruction (module docs). Prints the calibration.
    pub fn start(mut syst: SYST) -> Result<Self, CalibrationError> {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(COUNTER_MASK);
        syst.clear_current();
        syst.enable_counter();

        let overhead_ticks = (0..8).map(|_| ticks_of(&mut || {})).min().unwrap_or(0);
        let short = ticks_of(&mut || spin(CAL_SHORT));
        let mid = ticks_of(&mut || spin(CAL_MID));
        let long = ticks_of(&mut || spin(CAL_LONG));
        let first = mid.wrapping_sub(short);
        let second = long.wrapping_sub(mid);
        // Both differences are 2000 instructions; allow one tick of rounding.
        if first == 0 || first.abs_diff(second) > 1 {
            return Err(CalibrationError::NotLinear { first, second });
        }
        let cal_ticks = long - short;
        let milli = u64::from(cal_ticks) * 1000 / u64::from(CAL_INSTRUCTIONS);
        hprintln!(
            "calibration: {} instructions (asm loop) = {} SysTick ticks, \
             {}.{:03} ticks/instruction; frame overhead {} ticks",
            CAL_INSTRUCTIONS,
            cal_ticks,
            milli / 1000,
            milli % 1000,
            overhead_ticks
        );
        Ok(Self {
            cal_ticks,
            overhead_ticks,
        })
    }

    /// Instructions retired by one call of `f`, the measurement frame's overhead removed
    /// (rounded to the nearest instruction).
    pub fn count(&self, f: &mut dyn FnMut()) -> u32 {
        let ticks = ticks_of(f).saturating_sub(self.overhead_ticks);
        let num = u64::from(ticks) * u64::from(CAL_INSTRUCTIONS) * 2 + u64::from(self.cal_ticks);
        let instr = num / (2 * u64::from(self.cal_ticks));
        u32::try_from(instr).unwrap_or(u32::MAX)
    }

    /// Counts `calls` calls of `f(k)`, `k = 0, 1, ..`, and prints the result under `name`
    /// ([`Tally::report`]). The one-line way to add a measured function (its count includes
    /// what `f` does with `k`, e.g. indexing; no line uses it at present).
    #[allow(dead_code)]
    pub fn measure(&self, name: &str, calls: usize, mut f: impl FnMut(usize)) -> Summary {
        let mut tally = Tally::new();
        for k in 0..calls.min(MAX_CALLS) {
            tally.push(self.count(&mut || f(k)));
        }
        tally.report(name)
    }
}

/// Statistics of the per-call counts (all deterministic under `-icount`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Summary {
    /// Number of calls.
    pub calls: usize,
    /// Median instructions per call (the lower middle value for an even count).
    pub median: u32,
    /// Sum of the counts (the mean is `total / calls`).
    pub total: u64,
    /// Fewest instructions of one call.
    pub min: u32,
    /// Most instructions of one call.
    pub max: u32,
}

/// Per-call instruction counts of one function.
pub struct Tally {
    counts: [u32; MAX_CALLS],
    len: usize,
}

impl Tally {
    /// An empty tally.
    pub fn new() -> Self {
        Self {
            counts: [0; MAX_CALLS],
            len: 0,
        }
    }

    /// Records one call (ignored beyond [`MAX_CALLS`]).
    pub fn push(&mut self, instructions: u32) {
        if let Some(slot) = self.counts.get_mut(self.len) {
            *slot = instructions;
            self.len += 1;
        }
    }

    /// Statistics of the recorded calls.
    pub fn summary(&self) -> Summary {
        let mut sorted = self.counts;
        let recorded = sorted.get_mut(..self.len).unwrap_or_default();
        recorded.sort_unstable();
        let mid = recorded.len().saturating_sub(1) / 2;
        Summary {
            calls: recorded.len(),
            median: recorded.get(mid).copied().unwrap_or(0),
            total: recorded.iter().map(|&c| u64::from(c)).sum(),
            min: recorded.first().copied().unwrap_or(0),
            max: recorded.last().copied().unwrap_or(0),
        }
    }

    /// Prints `cortex-m4 <name>: <median> instructions/call` (the line the benchmark and the
    /// QEMU script read) and a detail line, and returns the statistics.
    pub fn report(&self, name: &str) -> Summary {
        let s = self.summary();
        let calls = s.calls.max(1) as u64;
        let mean10 = (s.total * 10 + calls / 2) / calls;
        hprintln!("cortex-m4 {}: {} instructions/call", name, s.median);
        hprintln!(
            "    {}: median {}, mean {}.{}, min {}, max {} over {} calls",
            name,
            s.median,
            mean10 / 10,
            mean10 % 10,
            s.min,
            s.max,
            s.calls
        );
        s
    }
}

/// Instruction counts of any number of calls (a [`Tally`] keeps at most [`MAX_CALLS`]): the
/// worst, the mean and the exact median, from a histogram with one bin per instruction up to
/// [`Histogram::BINS`] (a call above it counts in the last bin; the worst is kept exactly).
pub struct Histogram {
    bins: [u32; Histogram::BINS],
    calls: u32,
    total: u64,
    min: u32,
    max: u32,
    /// Which call was the worst (0-based).
    worst_call: u32,
}

impl Histogram {
    /// Bins: counts `0 ..= BINS - 1` instructions.
    pub const BINS: usize = 8192;

    /// An empty histogram.
    pub fn new() -> Self {
        Self {
            bins: [0; Self::BINS],
            calls: 0,
            total: 0,
            min: u32::MAX,
            max: 0,
            worst_call: 0,
        }
    }

    /// Records one call.
    pub fn push(&mut self, instructions: u32) {
        let bin = (instructions as usize).min(Self::BINS - 1);
        if let Some(b) = self.bins.get_mut(bin) {
            *b += 1;
        }
        if instructions > self.max || self.calls == 0 {
            self.worst_call = self.calls;
        }
        self.calls += 1;
        self.total += u64::from(instructions);
        self.min = self.min.min(instructions);
        self.max = self.max.max(instructions);
    }

    /// Which call (0-based) was the worst.
    pub fn worst_call(&self) -> u32 {
        self.worst_call
    }

    /// Statistics of the recorded calls (the median as [`Tally::summary`]'s: the lower
    /// middle value).
    pub fn summary(&self) -> Summary {
        let rank = self.calls.saturating_sub(1) / 2;
        let mut seen = 0u32;
        let mut median = 0u32;
        for (i, &n) in self.bins.iter().enumerate() {
            seen += n;
            if n > 0 && seen > rank {
                median = i as u32;
                break;
            }
        }
        Summary {
            calls: self.calls as usize,
            median,
            total: self.total,
            min: if self.calls == 0 { 0 } else { self.min },
            max: self.max,
        }
    }
}

//! The register-access module: every `unsafe` of the firmware is here, on the `stm32g4` PAC.
//!
//! # Rules that make it sound
//!
//! - [`init`] runs once, first, with the interrupts off; it owns the peripherals then.
//! - Afterwards the control interrupt (`ADC1_2`, the only interrupt enabled) is the only
//!   code that touches TIM1's compare and output-enable registers and the ADC data registers
//!   ([`Pwm`], [`read_samples`], [`break_fired`]); the main loop touches only USART2
//!   ([`uart_read`], [`uart_write`]), the watchdog ([`feed_watchdog`]) and the flash
//!   ([`write_record`], called with the PWM off and the control interrupt masked by the
//!   caller's critical section). Each register is thus written from one context only, which
//!   is why reaching a peripheral through its `ptr()` outside [`init`] is sound here.
//! - Raw pointers: only the flash record's page is read ([`read_record`]) and programmed.
//!
//! # The hardware as set up
//!
//! - **Clock**: HSI16 -> PLL (/4 x85 /2) = 170 MHz in range-1 boost mode, flash 4 wait
//!   states with prefetch and caches.
//! - **TIM1**: center-aligned mode 1, ARR = [`PWM_ARR`], complementary outputs CH1..3 /
//!   CH1N..3N, dead time [`DEAD_TIME_NS`], compare registers preloaded. The repetition
//!   counter makes one update event per period, at the counter's peak (the low switches
//!   conduct): the compare values written in the interrupt load there, and the update is
//!   TRGO, the ADC's injected trigger. The break is enabled with the outputs' idle level
//!   low (all six switches off): MOE is off from reset and is set only by [`Pwm::enable`];
//!   the system break (core lockup, SRAM parity, flash ECC) cuts the outputs. The board has
//!   no external fault line on a BKIN pin, and the internal comparators (COMP1/2/4 with DAC
//!   thresholds into BRK2, a hardware over-current trip) are not set up: foc's software
//!   over-current check and the supply's current limit are the over-current protection. OSSI/OSSR
//!   keep the pins driven low while the outputs are off.
//! - **Op-amps** 1..3: PGA gain 16 on VINP0 (PA1, PA7, PB0) with the board's bias network on
//!   VINM0 (PA3, PA5, PB2), outputs on their pins (PA2, PA6, PB1), high-speed mode.
//! - **ADC1** injected, on TIM1 TRGO: IN3 (PA2, phase a), IN12 (PB1, phase c), IN1 (PA0, bus),
//!   IN5 (PB14, temperature). **ADC2** injected, same trigger: IN3 (PA6, phase b). The end of
//!   ADC1's injected sequence raises `ADC1_2`. Clock HCLK/4 = 42.5 MHz; the current channels
//!   sample for 6.5 cycles, the dividers for 47.5.
//! - **USART2** (PB3 TX, PB4 RX, the ST-LINK virtual COM port): [`UART_BAUD`], 8N1, FIFOs on.
//! - **IWDG**: LSI 32 kHz / 32, reload for [`WATCHDOG_MS`].
//! - **HardFault** (also the end of a panic): clears MOE before anything else, then waits
//!   for the watchdog's reset.

use board_b_g431b_esc1::config::{
    DEAD_TIME_NS, MAX_DUTY, PWM_ARR, SYSCLK_HZ, UART_BAUD, WATCHDOG_MS,
};
use board_b_g431b_esc1::control::Raw;
use board_b_g431b_esc1::record::RECORD_LEN;
use foc::hal::Inverter;
use stm32g4::stm32g431 as pac;

/// Address of the motor record: the last 2 KiB page of the 128 KiB flash (page 63).
const RECORD_ADDR: u32 = 0x0801_F800;
const RECORD_PAGE: u8 = 63;

/// Sets `pin` of `gpio` to alternate function `af`, very high speed.
macro_rules! pin_af {
    ($gpio:expr, $pin:expr, $af:expr) => {{
        let g = $gpio;
        let (pin, af): (u32, u32) = ($pin, $af);
        g.ospeedr()
            .modify(|r, w| unsafe { w.bits(r.bits() | (3 << (2 * pin))) });
        if pin < 8 {
            g.afrl().modify(|r, w| unsafe {
                w.bits((r.bits() & !(0xF << (4 * pin))) | (af << (4 * pin)))
            });
        } else {
            let p = pin.wrapping_sub(8) & 7;
            g.afrh()
                .modify(|r, w| unsafe { w.bits((r.bits() & !(0xF << (4 * p))) | (af << (4 * p))) });
        }
        g.moder()
            .modify(|r, w| unsafe { w.bits((r.bits() & !(3 << (2 * pin))) | (2 << (2 * pin))) });
    }};
}

/// Busy-waits about `us` microseconds at 170 MHz (init only).
fn delay_us(us: u32) {
    cortex_m::asm::delay(us * (SYSCLK_HZ / 1_000_000));
}

/// What [`init`] found.
pub struct Reset {
    /// The last reset was by the independent watchdog.
    pub by_watchdog: bool,
}

/// Sets up clock, pins, TIM1 (outputs off, break armed), op-amps, ADCs, USART2 and the
/// watchdog (module docs), then unmasks the control interrupt. PWM stays off.
pub fn init(dp: pac::Peripherals) -> Reset {
    let rcc = &dp.RCC;
    let by_watchdog = rcc.csr().read().iwdgrstf().bit_is_set();
    rcc.csr().modify(|_, w| w.rmvf().set_bit());

    // Clock: 170 MHz, boost mode (RM0440 6.1.5: AHB /2 while switching, then /1).
    rcc.apb1enr1().modify(|_, w| w.pwren().set_bit());
    rcc.apb2enr().modify(|_, w| w.syscfgen().set_bit());
    dp.PWR.cr5().modify(|_, w| w.r1mode().clear_bit());
    // The USB-C dead-battery pull-downs sit on PB4 (USART2 RX) and PB6 from reset: off.
    dp.PWR.cr3().modify(|_, w| w.ucpd1_dbdis().set_bit());
    dp.FLASH.acr().modify(|_, w| unsafe {
        w.latency()
            .bits(4)
            .prften()
            .set_bit()
            .icen()
            .set_bit()
            .dcen()
            .set_bit()
    });
    while dp.FLASH.acr().read().latency().bits() != 4 {}
    rcc.pllcfgr().write(|w| unsafe {
        w.pllsrc()
            .bits(0b10)
            .pllm()
            .set(3)
            .plln()
            .bits(85)
            .pllr()
            .set(0)
            .pllren()
            .set_bit()
    });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    while rcc.cr().read().pllrdy().bit_is_clear() {}
    rcc.cfgr().modify(|_, w| w.hpre().set(0b1000));
    rcc.cfgr().modify(|_, w| w.sw().set(0b11));
    while rcc.cfgr().read().sws().bits() != 0b11 {}
    delay_us(2);
    rcc.cfgr().modify(|_, w| w.hpre().set(0));

    rcc.ahb2enr().modify(|_, w| {
        w.gpioaen()
            .set_bit()
            .gpioben()
            .set_bit()
            .gpiocen()
            .set_bit()
            .adc12en()
            .set_bit()
    });
    rcc.apb2enr().modify(|_, w| w.tim1en().set_bit());
    rcc.apb1enr1().modify(|_, w| w.usart2en().set_bit());
    // The system break sources into TIM1's break: core lockup, SRAM parity, flash ECC.
    dp.SYSCFG
        .cfgr2()
        .modify(|_, w| w.cll().set_bit().spl().set_bit().eccl().set_bit());

    init_tim1(&dp.TIM1);
    // TIM1 pins only now that its outputs are defined (off, driven low).
    pin_af!(&dp.GPIOA, 8, 6); // CH1  phase a high
    pin_af!(&dp.GPIOA, 9, 6); // CH2  phase b high
    pin_af!(&dp.GPIOA, 10, 6); // CH3 phase c high
    pin_af!(&dp.GPIOC, 13, 4); // CH1N phase a low
    pin_af!(&dp.GPIOA, 12, 6); // CH2N phase b low
    pin_af!(&dp.GPIOB, 15, 4); // CH3N phase c low
    init_opamps(&dp.OPAMP);
    init_adcs(&dp.ADC1, &dp.ADC2, &dp.ADC12_COMMON);
    pin_af!(&dp.GPIOB, 3, 7); // USART2 TX
    pin_af!(&dp.GPIOB, 4, 7); // USART2 RX
    init_uart(&dp.USART2);
    init_watchdog(&dp.IWDG);
    // Start: the counter runs (outputs off), the ADCs wait for its trigger.
    dp.TIM1.cr1().modify(|_, w| w.cen().set_bit());
    dp.ADC1.cr().modify(|_, w| w.jadstart().set_bit());
    dp.ADC2.cr().modify(|_, w| w.jadstart().set_bit());
    // SAFETY: the handler exists (main.rs) and every state it uses is set up.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::ADC1_2) };
    Reset { by_watchdog }
}

fn init_tim1(t: &pac::TIM1) {
    t.psc().write(|w| unsafe { w.bits(0) });
    t.arr().write(|w| w.arr().set(u32::from(PWM_ARR)));
    // Center-aligned mode 1, auto-reload preloaded.
    t.cr1().write(|w| w.cms().set(0b01).arpe().set_bit());
    // PWM mode 1 (high while CNT < CCR), compare preloaded.
    t.ccmr1_output().write(|w| {
        w.oc1m()
            .set(0b110)
            .oc1pe()
            .set_bit()
            .oc2m()
            .set(0b110)
            .oc2pe()
            .set_bit()
    });
    t.ccmr2_output()
        .write(|w| w.oc3m().set(0b110).oc3pe().set_bit());
    let half = u32::from(PWM_ARR / 2);
    t.ccr1().write(|w| unsafe { w.bits(half) });
    t.ccr2().write(|w| unsafe { w.bits(half) });
    t.ccr3().write(|w| unsafe { w.bits(half) });
    t.ccer().write(|w| {
        w.cc1e()
            .set_bit()
            .cc1ne()
            .set_bit()
            .cc2e()
            .set_bit()
            .cc2ne()
            .set_bit();
        w.cc3e().set_bit().cc3ne().set_bit()
    });
    // Idle levels low (OIS = 0); TRGO on update.
    t.cr2().write(|w| unsafe { w.mms().bits(0b010) });
    // Dead time: DTG < 128 counts t_DTS = 1 / 170 MHz.
    let dtg = (DEAD_TIME_NS * (SYSCLK_HZ / 1_000_000) / 1000).min(127) as u8;
    t.bdtr().write(|w| {
        w.dtg()
            .set(dtg)
            .ossi()
            .set_bit()
            .ossr()
            .set_bit()
            .bke()
            .set_bit()
            .bkp()
            .set_bit()
    });
    // One update per period, at the peak: REP_CNT = 0 now, RCR = 1 from the next update
    // (RM0440 28.3.3, repetition counter in center-aligned mode).
    // The break comes from the system sources only (no BKIN pin on this board).
    t.af1().modify(|_, w| w.bkine().clear_bit());
    t.rcr().write(|w| w.rep().set(0));
    t.egr().write(|w| w.ug().set_bit());
    t.rcr().write(|w| w.rep().set(1));
    t.sr().write(|w| unsafe { w.bits(0) });
}

fn init_opamps(o: &pac::OPAMP) {
    // VP = VINP0, VM = PGA, gain 16 with VINM0 for the external network, high speed, output
    // to the pin (RM0440 24.5.1).
    o.opamp1_csr().write(|w| unsafe {
        w.vp_sel()
            .set(0)
            .vm_sel()
            .set(0b10)
            .pga_gain()
            .bits(0b01011)
            .opahsm()
            .set_bit()
    });
    o.opamp2_csr().write(|w| unsafe {
        w.vp_sel()
            .set(0)
            .vm_sel()
            .set(0b10)
            .pga_gain()
            .bits(0b01011)
            .opahsm()
            .set_bit()
    });
    o.opamp3_csr().write(|w| unsafe {
        w.vp_sel()
            .set(0)
            .vm_sel()
            .set(0b10)
            .pga_gain()
            .bits(0b01011)
            .opahsm()
            .set_bit()
    });
    o.opamp1_csr().modify(|_, w| w.opaen().set_bit());
    o.opamp2_csr().modify(|_, w| w.opaen().set_bit());
    o.opamp3_csr().modify(|_, w| w.opaen().set_bit());
}

fn init_adcs(a1: &pac::ADC1, a2: &pac::ADC2, common: &pac::ADC12_COMMON) {
    // HCLK / 4, synchronous.
    common.ccr().write(|w| w.ckmode().set(0b11));
    for adc in [&**a1, &**a2] {
        adc.cr().write(|w| w.deeppwd().clear_bit());
        adc.cr().write(|w| w.advregen().set_bit());
    }
    delay_us(25);
    for adc in [&**a1, &**a2] {
        adc.cr()
            .modify(|_, w| w.adcaldif().clear_bit().adcal().set_bit());
        while adc.cr().read().adcal().bit_is_set() {}
    }
    delay_us(1);
    for adc in [&**a1, &**a2] {
        adc.isr().write(|w| w.adrdy().clear_bit_by_one());
        adc.cr().modify(|_, w| w.aden().set_bit());
        while adc.isr().read().adrdy().bit_is_clear() {}
        // Injected queue off: JSQR is the sequence.
        adc.cfgr().write(|w| w.jqdis().set_bit());
    }
    // Sample times: 6.5 cycles (001) for IN3 and IN12, 47.5 (100) for IN1 and IN5.
    a1.smpr1()
        .write(|w| w.smp1().set(0b100).smp3().set(0b001).smp5().set(0b100));
    a1.smpr2().write(|w| w.smp12().set(0b001));
    a2.smpr1().write(|w| w.smp3().set(0b001));
    // JL = n - 1, JEXTSEL 0 = TIM1_TRGO, JEXTEN 01 = rising edge.
    a1.jsqr().write(|w| unsafe {
        w.jl().set(3).jextsel().bits(0).jexten().set(0b01);
        w.jsq1()
            .bits(3)
            .jsq2()
            .bits(12)
            .jsq3()
            .bits(1)
            .jsq4()
            .bits(5)
    });
    a2.jsqr().write(|w| unsafe {
        w.jl()
            .set(0)
            .jextsel()
            .bits(0)
            .jexten()
            .set(0b01)
            .jsq1()
            .bits(3)
    });
    a1.ier().write(|w| w.jeosie().set_bit());
}

fn init_uart(u: &pac::USART2) {
    u.brr()
        .write(|w| w.brr().set((SYSCLK_HZ / UART_BAUD) as u16));
    u.cr1().write(|w| {
        w.fifoen()
            .set_bit()
            .te()
            .set_bit()
            .re()
            .set_bit()
            .ue()
            .set_bit()
    });
}

fn init_watchdog(iwdg: &pac::IWDG) {
    let reload = WATCHDOG_MS.min(4095) as u16;
    iwdg.kr().write(|w| unsafe { w.key().bits(0xCCCC) });
    iwdg.kr().write(|w| unsafe { w.key().bits(0x5555) });
    // 32 kHz / 32 = 1 kHz: the reload value is in ms.
    iwdg.pr().write(|w| w.pr().set(0b011));
    iwdg.rlr().write(|w| w.rl().set(reload));
    while iwdg.sr().read().bits() != 0 {}
    iwdg.kr().write(|w| unsafe { w.key().bits(0xAAAA) });
}

/// Reloads the watchdog.
pub fn feed_watchdog() {
    // SAFETY: module docs (main loop only).
    let iwdg = unsafe { &*pac::IWDG::ptr() };
    iwdg.kr().write(|w| unsafe { w.key().bits(0xAAAA) });
}

/// The period's samples; clears the end-of-sequence flag. (Control interrupt only.)
pub fn read_samples() -> Raw {
    // SAFETY: module docs (control interrupt only).
    let (a1, a2) = unsafe { (&*pac::ADC1::ptr(), &*pac::ADC2::ptr()) };
    a1.isr()
        .write(|w| w.jeos().clear_bit_by_one().jeoc().clear_bit_by_one());
    a2.isr()
        .write(|w| w.jeos().clear_bit_by_one().jeoc().clear_bit_by_one());
    Raw {
        i: [
            a1.jdr1().read().jdata().bits(),
            a2.jdr1().read().jdata().bits(),
            a1.jdr2().read().jdata().bits(),
        ],
        vbus: a1.jdr3().read().jdata().bits(),
        temp: a1.jdr4().read().jdata().bits(),
    }
}

/// Whether TIM1's break (or system break) fired since the last call; clears the flags.
pub fn break_fired() -> bool {
    // SAFETY: module docs (control interrupt only).
    let t = unsafe { &*pac::TIM1::ptr() };
    let sr = t.sr().read();
    let fired = sr.bif().bit_is_set() || sr.sbif().bit_is_set();
    if fired {
        t.sr().write(|w| unsafe { w.bits(!((1 << 7) | (1 << 13))) });
    }
    fired
}

/// TIM1's outputs as foc's [`Inverter`]. (Control interrupt only.)
pub struct Pwm;

impl Inverter for Pwm {
    fn set_duties(&mut self, d: [f32; 3]) {
        // SAFETY: module docs (control interrupt only).
        let t = unsafe { &*pac::TIM1::ptr() };
        let arr = f32::from(PWM_ARR);
        let c = d.map(|x| {
            let x = if x.is_nan() {
                0.5
            } else {
                x.clamp(0.0, MAX_DUTY)
            };
            (x * arr) as u32
        });
        t.ccr1().write(|w| unsafe { w.bits(c[0]) });
        t.ccr2().write(|w| unsafe { w.bits(c[1]) });
        t.ccr3().write(|w| unsafe { w.bits(c[2]) });
    }

    fn enable(&mut self, on: bool) {
        // SAFETY: module docs (control interrupt only).
        let t = unsafe { &*pac::TIM1::ptr() };
        let sr = t.sr().read();
        if on && sr.bif().bit_is_clear() && sr.sbif().bit_is_clear() {
            t.bdtr().modify(|_, w| w.moe().set_bit());
        } else {
            t.bdtr().modify(|_, w| w.moe().clear_bit());
        }
    }
}

/// A received byte, if any (clears an overrun). (Main loop only.)
pub fn uart_read() -> Option<u8> {
    // SAFETY: module docs (main loop only).
    let u = unsafe { &*pac::USART2::ptr() };
    let isr = u.isr().read();
    if isr.ore().bit_is_set() {
        u.icr().write(|w| w.orecf().clear_bit_by_one());
    }
    if isr.rxne().bit_is_set() {
        Some(u.rdr().read().bits() as u8)
    } else {
        None
    }
}

/// Sends `bytes`, waiting for room in the FIFO. (Main loop only.)
pub fn uart_write(bytes: &[u8]) {
    // SAFETY: module docs (main loop only).
    let u = unsafe { &*pac::USART2::ptr() };
    for &b in bytes {
        while u.isr().read().txe().bit_is_clear() {}
        u.tdr().write(|w| unsafe { w.bits(u32::from(b)) });
    }
}

/// The record page's first bytes.
pub fn read_record() -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    for (i, b) in out.iter_mut().enumerate() {
        // SAFETY: reads inside the flash's record page (memory.x reserves it).
        *b = unsafe { core::ptr::read_volatile((RECORD_ADDR as usize + i) as *const u8) };
    }
    out
}

/// Why a flash write failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// The flash reported an error (its status register's bits).
    Status(u32),
    /// What was written does not read back.
    Verify,
}

/// Erases the record page and programs `rec` (`None`: erase only). Stalls the CPU for the
/// erase (about 22 ms): the caller holds the PWM off and masks the control interrupt.
pub fn write_record(rec: Option<&[u8; RECORD_LEN]>) -> Result<(), FlashError> {
    // SAFETY: module docs (main loop, PWM off).
    let f = unsafe { &*pac::FLASH::ptr() };
    const ERRORS: u32 = 0xC3FA; // OPERR PROGERR WRPERR PGAERR SIZERR PGSERR MISERR FASTERR RDERR OPTVERR
    while f.sr().read().bsy().bit_is_set() {}
    f.sr().write(|w| unsafe { w.bits(ERRORS) });
    if f.cr().read().lock().bit_is_set() {
        f.keyr().write(|w| unsafe { w.bits(0x4567_0123) });
        f.keyr().write(|w| unsafe { w.bits(0xCDEF_89AB) });
    }
    f.cr()
        .write(|w| unsafe { w.per().set_bit().pnb().bits(RECORD_PAGE) });
    f.cr().modify(|_, w| w.strt().set_bit());
    while f.sr().read().bsy().bit_is_set() {}
    f.cr().write(|w| w.per().clear_bit());
    let mut result = Ok(());
    let status = f.sr().read().bits() & ERRORS;
    if status != 0 {
        result = Err(FlashError::Status(status));
    } else if let Some(bytes) = rec {
        f.cr().write(|w| w.pg().set_bit());
        for (k, dw) in bytes.chunks_exact(8).enumerate() {
            let addr = (RECORD_ADDR as usize + 8 * k) as *mut u32;
            let lo = u32::from_le_bytes([dw[0], dw[1], dw[2], dw[3]]);
            let hi = u32::from_le_bytes([dw[4], dw[5], dw[6], dw[7]]);
            // SAFETY: a double word of the erased record page, programmed as RM0440 5.3.7
            // asks (two word writes, low address first).
            unsafe {
                core::ptr::write_volatile(addr, lo);
                core::ptr::write_volatile(addr.add(1), hi);
            }
            while f.sr().read().bsy().bit_is_set() {}
            let status = f.sr().read().bits() & ERRORS;
            if status != 0 {
                result = Err(FlashError::Status(status));
                break;
            }
        }
        f.cr().write(|w| w.pg().clear_bit());
    }
    f.cr().write(|w| w.lock().set_bit());
    // The data cache may hold the page's old contents (read at reset): flush it.
    f.acr().modify(|_, w| w.dcen().clear_bit());
    f.acr().modify(|_, w| w.dcrst().set_bit());
    f.acr()
        .modify(|_, w| w.dcrst().clear_bit().dcen().set_bit());
    if let (Ok(()), Some(bytes)) = (result, rec)
        && read_record() != *bytes
    {
        result = Err(FlashError::Verify);
    }
    result
}

/// A panic (panic-probe ends in `udf`) or any fault lands here: the outputs off first, then
/// wait for the watchdog's reset.
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    // SAFETY: whatever ran is abandoned; clearing MOE cuts all six switches.
    let t = unsafe { &*pac::TIM1::ptr() };
    t.bdtr().modify(|_, w| w.moe().clear_bit());
    loop {
        cortex_m::asm::nop();
    }
}

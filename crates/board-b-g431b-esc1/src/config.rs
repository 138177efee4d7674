//! The board's numbers (B-G431B-ESC1, ST's user manual UM2516 and schematic) and the drive
//! configuration built from them. Hardware-independent: the raw-to-SI conversions are tested
//! on the host.
//!
//! | quantity | value | where from |
//! |---|---|---|
//! | system clock | 170 MHz (HSI16 -> PLL x85 / 4 / 2) | RM0440 |
//! | PWM | 20 kHz, center-aligned: ARR = 170 MHz / (2 x 20 kHz) = 4250 | [`PWM_HZ`] |
//! | dead time | 500 ns (85 timer clocks) | [`DEAD_TIME_NS`] |
//! | largest duty | 0.94: the low switch conducts at least 3 us around the sample point; the current loops' limit 0.88 `u_dc / sqrt(3)` | [`MAX_DUTY`], [`MAX_MODULATION`] |
//! | shunts | 3 mOhm, op-amp PGA gain 16 with the board's bias network: -9.14 V/V | [`AMPS_PER_COUNT`] |
//! | bus divider | 18 k / (18 k + 169 k) = 0.0963 | [`VOLTS_PER_COUNT`] |
//! | ADC | 12 bit, 3.3 V reference | |
//! | bus voltage | 8 V to 25 V (6S LiPo at most) | [`U_DC_MIN_V`], [`U_DC_MAX_V`] |
//! | phase current | 40 A peak (board rating); the drive's limit here is far lower | [`CURRENT_LIMIT_A`] |

use foc::ekf_core::MotorParams;
use foc::{ComputationDelay, FocConfig};

/// System clock, Hz.
pub const SYSCLK_HZ: u32 = 170_000_000;
/// PWM frequency, Hz.
pub const PWM_HZ: u32 = 20_000;
/// PWM period, s (one `Foc::tick` per period).
pub const TS_S: f32 = 1.0 / PWM_HZ as f32;
/// TIM1 auto-reload value: center-aligned, the counter goes up and down once per period.
pub const PWM_ARR: u16 = (SYSCLK_HZ / (2 * PWM_HZ)) as u16;
/// Dead time between the high and low switch of a leg, ns.
pub const DEAD_TIME_NS: u32 = 500;
/// Largest duty: the low-side switch conducts at least this long around the sample point
/// (the op-amp output settles in about 1.3 us after the switching edge).
pub const MAX_DUTY: f32 = 0.94;

/// ADC full scale, counts.
pub const ADC_FULL_SCALE: f32 = 4095.0;
/// ADC reference, V.
pub const ADC_VREF_V: f32 = 3.3;
/// Current per ADC count: `3.3 V / 4095 / (0.003 ohm x -9.14)`, A. The sign: the amplifier
/// inverts (a current out of the phase reads below mid-scale).
pub const AMPS_PER_COUNT: f32 = ADC_VREF_V / ADC_FULL_SCALE / (0.003 * -9.14);
/// Bus voltage per ADC count: `3.3 V / 4095 x (18 k + 169 k) / 18 k`, V.
pub const VOLTS_PER_COUNT: f32 = ADC_VREF_V / ADC_FULL_SCALE * (18.0 + 169.0) / 18.0;
/// Nominal ADC reading at zero current (the bias the op-amp network adds), counts; the
/// measured offsets replace it.
pub const CURRENT_ZERO_COUNTS: f32 = 2048.0;

/// Lowest bus voltage the drive starts and runs on, V.
pub const U_DC_MIN_V: f32 = 8.0;
/// Highest bus voltage, V.
pub const U_DC_MAX_V: f32 = 25.0;
/// Nominal bus voltage the controller's gains are sized for, V.
pub const U_DC_NOMINAL_V: f32 = 12.0;
/// The drive's phase current limit, A (a bench setting: the board takes 40 A peak).
pub const CURRENT_LIMIT_A: f32 = 5.0;
/// Software over-current trip, A.
pub const OVER_CURRENT_A: f32 = 8.0;
/// Test current of the identification, A.
pub const IDENTIFY_CURRENT_A: f32 = 2.0;
/// Largest accepted current offset (at PWM off) from the nominal mid-scale, A.
pub const MAX_OFFSET_A: f32 = 2.0;
/// Largest current any phase may read at PWM off before switching, A.
pub const MAX_IDLE_CURRENT_A: f32 = 0.5;
/// Power-stage temperature above which the drive does not start, degC.
pub const MAX_TEMPERATURE_C: f32 = 80.0;
/// Independent watchdog timeout, ms: the control interrupt and the main loop must both
/// have run within it (a flash page erase stalls the CPU for up to 40 ms).
pub const WATCHDOG_MS: u32 = 100;
/// UART baud rate (the ST-LINK virtual COM port).
pub const UART_BAUD: u32 = 921_600;

/// Phase current of a raw ADC reading with the measured zero `zero_counts`, A.
#[inline]
pub fn current_a(raw: u16, zero_counts: f32) -> f32 {
    (f32::from(raw) - zero_counts) * AMPS_PER_COUNT
}

/// Bus voltage of a raw ADC reading, V.
#[inline]
pub fn bus_voltage_v(raw: u16) -> f32 {
    f32::from(raw) * VOLTS_PER_COUNT
}

/// Temperature of the NTC divider reading, degC: linear fit of the board's NTC (10 k,
/// B = 3380) over 25..100 degC, `T = (V - 1.055 V) / 22.7 mV/degC + 25`. Good to a few
/// degrees in that range: enough for a start check.
#[inline]
pub fn temperature_c(raw: u16) -> f32 {
    let v = f32::from(raw) * (ADC_VREF_V / ADC_FULL_SCALE);
    (v - 1.055) / 0.0227 + 25.0
}

/// The motor the drive uses without a motor record: a small 7-pole-pair gimbal-class
/// motor (`Rs` 0.2 ohm, `L` 60 uH, `psi_f` 4 mWb). `start` identifies the real one first
/// when it can (feature `identify`).
pub fn builtin_motor() -> MotorParams<f32> {
    MotorParams {
        rs_ohm: 0.2,
        ld_h: 60e-6,
        lq_h: 60e-6,
        psi_f_wb: 0.004,
        pole_pairs: 7,
    }
}

/// The drive's configuration for `motor` on this board: foc's defaults for the motor, the
/// PWM period and the nominal bus ([`FocConfig::new`]), one period of computation delay
/// (preloaded duties), the bench current limit (the start-up currents cut to 80 % of it)
/// and the board's bus range.
pub fn drive_config(motor: MotorParams<f32>, inertia_kg_m2: Option<f32>) -> FocConfig {
    let mut cfg =
        FocConfig::new(motor, TS_S, U_DC_NOMINAL_V).with_delay(ComputationDelay::OnePeriod);
    if let Some(j) = inertia_kg_m2.filter(|j| j.is_finite() && *j > 0.0) {
        cfg = cfg.with_inertia(j);
    }
    let lim = cfg.current_limit_a.min(CURRENT_LIMIT_A);
    cfg.current_limit_a = lim;
    cfg.startup.align_current_a = cfg.startup.align_current_a.min(0.8 * lim);
    cfg.startup.if_current_a = cfg.startup.if_current_a.min(0.8 * lim);
    if let Some(i) = cfg.field_weakening.max_negative_id_a.as_mut() {
        *i = i.min(lim);
    }
    cfg.over_current_a = OVER_CURRENT_A;
    cfg.u_dc_min_v = U_DC_MIN_V;
    cfg.u_dc_max_v = U_DC_MAX_V + 1.0;
    cfg.dead_time_s = DEAD_TIME_NS as f32 * 1e-9;
    cfg.max_modulation = cfg.max_modulation.min(MAX_MODULATION);
    cfg
}

/// The current loops' voltage limit as a fraction of `u_dc / sqrt(3)`: the centred SVPWM's
/// largest duty is `0.5 + 0.5 m`, kept at [`MAX_DUTY`] so that the low switch conducts
/// around the sample point (the PWM driver clamps at `MAX_DUTY` too).
pub const MAX_MODULATION: f32 = 2.0 * MAX_DUTY - 1.0;

/// The identification's settings on this board for a motor of `pole_pairs` pole pairs: the
/// test current [`IDENTIFY_CURRENT_A`], a spin at 50 Hz electrical reached in 0.4 s, the
/// inertia measured.
#[cfg(feature = "identify")]
pub fn identify_config(pole_pairs: u8) -> foc::IdentifyConfig {
    let w_spin = core::f32::consts::TAU * 50.0;
    let mut cfg = foc::IdentifyConfig::new(TS_S, U_DC_NOMINAL_V, IDENTIFY_CURRENT_A)
        .with_spin(w_spin, w_spin / 0.4);
    cfg.over_current_a = OVER_CURRENT_A;
    cfg.u_dc_min_v = U_DC_MIN_V;
    cfg.u_dc_max_v = U_DC_MAX_V + 1.0;
    cfg.measure_inertia = true;
    cfg.pole_pairs = u32::from(pole_pairs);
    cfg.max_modulation = cfg.max_modulation.min(MAX_MODULATION);
    cfg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_match_the_board_numbers() {
        assert_eq!(PWM_ARR, 4250);
        // NuttX's and ST's figure: 1 / (R_shunt gain) = 36.47 A/V, inverted.
        assert!((AMPS_PER_COUNT * ADC_FULL_SCALE / ADC_VREF_V + 36.47).abs() < 0.01);
        assert_eq!(current_a(2048, 2048.0), 0.0);
        assert!(current_a(2000, 2048.0) > 0.0);
        // Full scale of the divider: 34.3 V.
        assert!((bus_voltage_v(4095) - 34.28).abs() < 0.01);
        assert!((temperature_c(1309) - 25.0).abs() < 0.5);
    }

    #[test]
    fn the_drive_and_identify_configs_are_accepted() {
        let cfg = drive_config(builtin_motor(), None);
        assert!(
            foc::Foc::new(&cfg).is_ok(),
            "{:?}",
            foc::Foc::new(&cfg).err()
        );
        assert!(cfg.current_limit_a <= CURRENT_LIMIT_A);
        // The largest duty of the centred SVPWM stays at the sampling limit.
        let d = foc::svpwm(
            foc::AlphaBeta {
                alpha: cfg.max_modulation * U_DC_NOMINAL_V / 3f32.sqrt(),
                beta: 0.0,
            },
            U_DC_NOMINAL_V,
        );
        assert!(
            d.duties.iter().all(|&x| x <= MAX_DUTY + 1e-4),
            "{:?}",
            d.duties
        );
        let cfg = drive_config(builtin_motor(), Some(3e-6));
        assert!(
            foc::Foc::new(&cfg).is_ok(),
            "{:?}",
            foc::Foc::new(&cfg).err()
        );
        #[cfg(feature = "identify")]
        {
            let id = identify_config(7);
            assert!(
                foc::Identifier::new(&id).is_ok(),
                "{:?}",
                foc::Identifier::new(&id).err()
            );
        }
    }
}

//! The firmware for ST's B-G431B-ESC1 (crate README): builds for `thumbv7em-none-eabihf`
//! only. The logic is in the library ([`board_b_g431b_esc1::control`]); this file wires it
//! to the hardware ([`hw`], the one module with `unsafe`): the control interrupt, the UART
//! command line, telemetry, the flash record and the watchdog.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
#![deny(unsafe_code)]

#[cfg(target_os = "none")]
#[allow(unsafe_code)]
mod hw;

#[cfg(target_os = "none")]
mod firmware {
    use core::cell::RefCell;
    use core::sync::atomic::{AtomicU32, Ordering};

    use critical_section::Mutex;
    use defmt_rtt as _;
    use panic_probe as _;
    use stm32g4::stm32g431::{self as pac, interrupt};

    use board_b_g431b_esc1::command::{Command, LineBuffer};
    use board_b_g431b_esc1::control::{Control, MotorSource, Reply};
    use board_b_g431b_esc1::record::MotorRecord;
    use board_b_g431b_esc1::telemetry::{LAYOUT_VERSION, MAX_FRAME, MetaFrame};

    use crate::hw;

    /// The controller, identification and supervisor, shared by the control interrupt and
    /// the main loop (which borrows it inside a critical section, briefly).
    static CONTROL: Mutex<RefCell<Option<Control>>> = Mutex::new(RefCell::new(None));
    /// Control periods run: the main loop feeds the watchdog only while this advances.
    static PERIODS: AtomicU32 = AtomicU32::new(0);

    /// The control interrupt: end of ADC1's injected sequence, once per PWM period.
    #[interrupt]
    fn ADC1_2() {
        let raw = hw::read_samples();
        let broke = hw::break_fired();
        critical_section::with(|cs| {
            if let Some(c) = CONTROL.borrow_ref_mut(cs).as_mut() {
                if broke {
                    c.broke();
                }
                c.period(raw, &mut hw::Pwm);
            }
        });
        PERIODS.fetch_add(1, Ordering::Relaxed);
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let Some(dp) = pac::Peripherals::take() else {
            panic!("peripherals taken twice");
        };
        let reset = hw::init(dp);
        let record = MotorRecord::decode(&hw::read_record());
        match &record {
            Ok(r) => defmt::info!(
                "motor record: Rs {} ohm, Ld {} H, Lq {} H, psi_f {} Wb, {} pole pairs",
                r.rs_ohm,
                r.ld_h,
                r.lq_h,
                r.psi_f_wb,
                r.pole_pairs
            ),
            Err(e) => defmt::info!("no motor record ({}): built-in motor", e.as_str()),
        }
        if reset.by_watchdog {
            defmt::error!("reset by the watchdog: fault latched, `clear` to go on");
        }
        let control = Control::new(record.ok(), reset.by_watchdog)
            .or_else(|_| Control::new(None, reset.by_watchdog));
        let Ok(control) = control else {
            // The built-in configuration is tested on the host; this cannot happen. PWM off.
            panic!("drive configuration refused");
        };
        critical_section::with(|cs| CONTROL.borrow_ref_mut(cs).replace(control));
        defmt::info!("ready: calibrating current offsets");

        let mut line = LineBuffer::new();
        let mut last_periods = 0;
        let mut frame = [0u8; MAX_FRAME];
        loop {
            // Watchdog: only while the control interrupt runs.
            let p = PERIODS.load(Ordering::Relaxed);
            if p != last_periods {
                last_periods = p;
                hw::feed_watchdog();
            }
            // Commands.
            while let Some(b) = hw::uart_read() {
                if let Some(parsed) = line.push(b) {
                    match parsed {
                        Ok(cmd) => handle(cmd),
                        Err(e) => reply(Err(e.as_str())),
                    }
                }
            }
            // A new motor record to store (PWM off).
            let pending = critical_section::with(|cs| {
                CONTROL
                    .borrow_ref_mut(cs)
                    .as_mut()
                    .and_then(Control::take_record)
            });
            if let Some(rec) = pending {
                let ok = critical_section::with(|_| hw::write_record(Some(&rec.encode())));
                if let Err(e) = ok {
                    defmt::error!("motor record write failed: {}", e);
                }
                let r = critical_section::with(|cs| {
                    CONTROL
                        .borrow_ref_mut(cs)
                        .as_mut()
                        .map(|c| c.record_written(rec, ok.is_ok()))
                });
                if let Some(r) = r {
                    reply(r);
                }
            }
            // Telemetry.
            let f = critical_section::with(|cs| {
                CONTROL
                    .borrow_ref_mut(cs)
                    .as_mut()
                    .and_then(Control::take_frame)
            });
            if let Some(f) = f {
                let n = f.encode(&mut frame);
                hw::uart_write(&frame[..n]);
            }
        }
    }

    /// Carries out a command and replies.
    fn handle(cmd: Command) {
        let r = critical_section::with(|cs| {
            CONTROL
                .borrow_ref_mut(cs)
                .as_mut()
                .map(|c| (c.command(cmd), c.foc().config().motor.pole_pairs))
        });
        let Some((r, pole_pairs)) = r else {
            return;
        };
        match (cmd, r) {
            (Command::Forget, Ok(_)) => {
                let e = critical_section::with(|_| hw::write_record(None));
                reply(
                    e.map(|()| "motor record erased")
                        .map_err(|_| "erase failed"),
                );
            }
            (Command::Telemetry { every }, Ok(_)) if every > 0 => {
                reply(r);
                let meta = MetaFrame {
                    ts_s: board_b_g431b_esc1::config::TS_S,
                    every,
                    pole_pairs: pole_pairs as u8,
                    layout: LAYOUT_VERSION,
                    u_dc_nominal_v: board_b_g431b_esc1::config::U_DC_NOMINAL_V,
                };
                let mut frame = [0u8; MAX_FRAME];
                let n = meta.encode(&mut frame);
                hw::uart_write(&frame[..n]);
            }
            (Command::Status, Ok(_)) => status(),
            _ => reply(r),
        }
    }

    /// `ok <text>` or `err <reason>`, one line; logged too.
    fn reply(r: Reply) {
        match r {
            Ok(t) => {
                defmt::info!("ok {}", t);
                hw::uart_write(b"ok ");
                hw::uart_write(t.as_bytes());
            }
            Err(t) => {
                defmt::warn!("err {}", t);
                hw::uart_write(b"err ");
                hw::uart_write(t.as_bytes());
            }
        }
        hw::uart_write(b"\n");
    }

    /// `ok state=<code> fault=<code> vbus_mv=<n> motor=<record|builtin> dropped=<n>`.
    fn status() {
        let s = critical_section::with(|cs| {
            CONTROL.borrow_ref_mut(cs).as_ref().map(|c| {
                let (state, fault) = c.codes();
                (
                    state,
                    fault,
                    c.idle().u_dc_v,
                    c.motor_source(),
                    c.dropped_frames(),
                )
            })
        });
        let Some((state, fault, u_dc, motor, dropped)) = s else {
            return;
        };
        let mut buf = [0u8; 10];
        hw::uart_write(b"ok state=");
        hw::uart_write(decimal(u32::from(state), &mut buf));
        hw::uart_write(b" fault=");
        hw::uart_write(decimal(u32::from(fault), &mut buf));
        hw::uart_write(b" vbus_mv=");
        let mv = if u_dc.is_finite() && u_dc > 0.0 {
            (u_dc * 1000.0) as u32
        } else {
            0
        };
        hw::uart_write(decimal(mv, &mut buf));
        hw::uart_write(match motor {
            MotorSource::Record => b" motor=record".as_slice(),
            MotorSource::Builtin => b" motor=builtin".as_slice(),
        });
        hw::uart_write(b" dropped=");
        hw::uart_write(decimal(dropped, &mut buf));
        hw::uart_write(b"\n");
    }

    /// `n` in decimal, in `buf`.
    fn decimal(mut n: u32, buf: &mut [u8; 10]) -> &[u8] {
        let mut i = buf.len();
        loop {
            i -= 1;
            buf[i] = b'0' + (n % 10) as u8;
            n /= 10;
            if n == 0 || i == 0 {
                break;
            }
        }
        &buf[i..]
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "board-b-g431b-esc1 is firmware for thumbv7em-none-eabihf: \
         cargo build -p board-b-g431b-esc1 --profile board --target thumbv7em-none-eabihf"
    );
    std::process::exit(2);
}

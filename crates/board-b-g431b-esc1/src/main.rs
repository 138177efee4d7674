#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod fw {
    use defmt_rtt as _;
    use foc::ekf_core::MotorParams;
    use foc::{Abc, Foc, FocConfig, Identifier, IdentifyConfig, PhaseCurrents, TickInput};
    use panic_probe as _;
    use stm32g4 as _;

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 24.0);
        let Ok(mut foc) = Foc::new(&cfg) else { loop {} };
        let Ok(mut id) = Identifier::new(&IdentifyConfig::new(50e-6, 24.0, 2.0)) else {
            loop {}
        };
        let _ = foc.start();
        loop {
            let a = unsafe { core::ptr::read_volatile(0x2000_0000 as *const f32) };
            let inp = TickInput {
                currents: PhaseCurrents::Abc(Abc { a, b: -a, c: 0.0 }),
                u_dc_v: 24.0,
                sensor: None,
            };
            let o = foc.tick(&inp);
            let p = id.tick(&inp);
            defmt::info!("{} {}", o.duties[0], p.duties[0]);
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("board-b-g431b-esc1: firmware for thumbv7em-none-eabihf only");
}

//! Test rig: a self-written SPMSM plant (f64, RK4 with substeps) driven by `Foc` with the
//! inverter's one-period computation delay. Independent of `ekf-core` and of `pmsm-sim`.
#![allow(dead_code)]

use ekf_core::testing::Rng;
use foc::ekf_core::MotorParams;
use foc::{AlphaBeta, Foc, FocConfig, State, TickInput, TickOutput, duties_to_alpha_beta};

/// Surface PMSM in alpha-beta, SI, electrical angle; mechanical speed state.
#[derive(Clone, Debug)]
pub struct Plant {
    pub rs: f64,
    pub ls: f64,
    pub psi: f64,
    pub p: f64,
    pub j: f64,
    pub b: f64,
    /// Load torque, N m, opposing positive torque (constant).
    pub load_nm: f64,
    /// Rotor held at standstill.
    pub locked: bool,
    /// [i_alpha, i_beta, w_mech, theta_e]
    pub x: [f64; 4],
}

impl Plant {
    /// The servo motor of docs/design.md, "Reference motors" (J 8e-4, B 1e-3).
    pub fn servo() -> Self {
        Self {
            rs: 2.875,
            ls: 8.5e-3,
            psi: 0.175,
            p: 4.0,
            j: 8e-4,
            b: 1e-3,
            load_nm: 0.0,
            locked: false,
            x: [0.0; 4],
        }
    }

    pub fn theta_e(&self) -> f64 {
        wrap(self.x[3])
    }

    pub fn omega_e(&self) -> f64 {
        self.p * self.x[2]
    }

    pub fn omega_mech(&self) -> f64 {
        self.x[2]
    }

    pub fn torque(&self, x: &[f64; 4]) -> f64 {
        let (s, c) = x[3].sin_cos();
        1.5 * self.p * self.psi * (-x[0] * s + x[1] * c)
    }

    fn deriv(&self, x: &[f64; 4], u: [f64; 2], open: bool) -> [f64; 4] {
        let we = self.p * x[2];
        let (s, c) = x[3].sin_cos();
        let (dia, dib) = if open {
            (0.0, 0.0)
        } else {
            (
                (-self.rs * x[0] + we * self.psi * s + u[0]) / self.ls,
                (-self.rs * x[1] - we * self.psi * c + u[1]) / self.ls,
            )
        };
        let dw = if self.locked {
            0.0
        } else {
            (self.torque(x) - self.b * x[2] - self.load_nm) / self.j
        };
        [dia, dib, dw, we]
    }

    /// Integrates over `dt` with the voltage `u` held (RK4, `n` substeps). `open`: bridge
    /// off, currents forced to zero (diodes not modelled).
    pub fn step(&mut self, u: [f64; 2], dt: f64, n: usize, open: bool) {
        if open {
            self.x[0] = 0.0;
            self.x[1] = 0.0;
        }
        let h = dt / n as f64;
        for _ in 0..n {
            let x = self.x;
            let add = |a: &[f64; 4], k: &[f64; 4], f: f64| {
                [
                    a[0] + f * k[0],
                    a[1] + f * k[1],
                    a[2] + f * k[2],
                    a[3] + f * k[3],
                ]
            };
            let k1 = self.deriv(&x, u, open);
            let k2 = self.deriv(&add(&x, &k1, h / 2.0), u, open);
            let k3 = self.deriv(&add(&x, &k2, h / 2.0), u, open);
            let k4 = self.deriv(&add(&x, &k3, h), u, open);
            for i in 0..4 {
                self.x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            if self.locked {
                self.x[2] = 0.0;
            }
        }
        self.x[3] = wrap(self.x[3]);
    }
}

pub fn wrap(x: f64) -> f64 {
    let tau = 2.0 * std::f64::consts::PI;
    x - tau * ((x + std::f64::consts::PI) / tau).floor()
}

/// The rig's noise seed: `FOC_TEST_SEED` from the environment when set (to check that a
/// test holds for the noise level, not for one realization:
/// `FOC_TEST_SEED=3 cargo test -p foc --release`), else 7.
pub fn noise_seed() -> u64 {
    std::env::var("FOC_TEST_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(7)
}

/// Plant + controller + inverter delay.
pub struct Rig {
    pub plant: Plant,
    pub foc: Foc,
    pub ts: f64,
    pub u_dc: f64,
    /// Duties computed by the last tick, applied over the next period (one-period delay).
    pub pending: ([f32; 3], bool),
    pub delay: bool,
    /// Current-sensor noise: the workspace's test generator, seeded by [`noise_seed`].
    pub noise: Rng,
    /// Current-sensor noise standard deviation per alpha-beta axis, A.
    pub noise_a: f64,
    /// Extra current added to the measured alpha current, A (fault injection).
    pub offset_a: f64,
    /// Measured beta current sign flipped (phases b and c swapped): fault injection.
    pub swap_bc: bool,
    pub sensored: bool,
    pub t: f64,
    pub substeps: usize,
    pub last: Option<TickOutput>,
    /// Plant angle and electrical speed at the last sample instant.
    pub sample_theta: f64,
    pub sample_omega_e: f64,
    /// Dead time of the bridge, s (0: ideal switches). Average model of pmsm-sim's inverter:
    /// leg x realizes `clamp01(d_x - sign(i_x) t_dead / Ts)`, the sign of the true phase
    /// current at the start of the period.
    pub dead_time_s: f64,
}

impl Rig {
    pub fn new(cfg: &FocConfig, plant: Plant, u_dc: f64) -> Self {
        Self {
            plant,
            foc: Foc::new(cfg).expect("valid config"),
            ts: f64::from(cfg.ts_s),
            u_dc,
            pending: ([0.5; 3], false),
            delay: cfg.delay == foc::ComputationDelay::OnePeriod,
            noise: Rng::new(noise_seed()),
            noise_a: 0.0,
            offset_a: 0.0,
            swap_bc: false,
            sensored: cfg.mode == foc::Mode::Sensored,
            t: 0.0,
            substeps: 4,
            last: None,
            sample_theta: 0.0,
            sample_omega_e: 0.0,
            dead_time_s: 0.0,
        }
    }

    /// Default servo rig at 20 kHz, 300 V, real J.
    pub fn servo_default() -> (FocConfig, Self) {
        let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 300.0).with_inertia(8e-4);
        let rig = Self::new(&cfg, Plant::servo(), 300.0);
        (cfg, rig)
    }

    /// Restarts the measurement noise from `seed`.
    pub fn reseed(&mut self, seed: u64) {
        self.noise = Rng::new(seed);
    }

    pub fn input(&mut self) -> TickInput {
        let ia = self.plant.x[0] + self.noise_a * self.noise.gauss() + self.offset_a;
        let mut ib = self.plant.x[1] + self.noise_a * self.noise.gauss();
        if self.swap_bc {
            ib = -ib;
        }
        let abc = AlphaBeta {
            alpha: ia as f32,
            beta: ib as f32,
        }
        .to_abc();
        let mut inp = TickInput::abc(abc.a, abc.b, abc.c, self.u_dc as f32);
        if self.sensored {
            inp = inp.with_sensor(self.plant.theta_e() as f32, self.plant.omega_e() as f32);
        }
        inp
    }

    /// One PWM period: sample, tick, apply (with or without the delay), integrate.
    pub fn step(&mut self) -> TickOutput {
        let inp = self.input();
        self.step_with(&inp)
    }

    pub fn step_with(&mut self, inp: &TickInput) -> TickOutput {
        self.sample_theta = self.plant.theta_e();
        self.sample_omega_e = self.plant.omega_e();
        let out = self.foc.tick(inp);
        let now = (out.duties, out.pwm_enabled);
        let applied = if self.delay {
            std::mem::replace(&mut self.pending, now)
        } else {
            now
        };
        // Output enable acts at once (the hardware's MOE); duties with the delay.
        let on = applied.1 && out.pwm_enabled;
        let u = if on && self.dead_time_s > 0.0 {
            let d = applied.0.map(f64::from);
            let f = self.dead_time_s / self.ts;
            let (ia, ib) = (self.plant.x[0], self.plant.x[1]);
            let h = 0.5 * 3f64.sqrt() * ib;
            let i = [ia, -0.5 * ia + h, -0.5 * ia - h];
            let e = [0, 1, 2].map(|x| {
                let sign = if i[x] > 0.0 {
                    1.0
                } else if i[x] < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                (d[x] - sign * f).clamp(0.0, 1.0)
            });
            // Clarke of the pole voltages (common mode removed).
            [
                (2.0 * e[0] - e[1] - e[2]) / 3.0 * self.u_dc,
                (e[1] - e[2]) / 3f64.sqrt() * self.u_dc,
            ]
        } else if on {
            let u = duties_to_alpha_beta(applied.0, self.u_dc as f32);
            [f64::from(u.alpha), f64::from(u.beta)]
        } else {
            [0.0, 0.0]
        };
        self.plant.step(u, self.ts, self.substeps, !on);
        self.t += self.ts;
        self.last = Some(out);
        out
    }

    /// Runs `seconds`, calling `f` after each tick; returns the last output.
    pub fn run(&mut self, seconds: f64, mut f: impl FnMut(&Self, &TickOutput)) -> TickOutput {
        let n = (seconds / self.ts).round() as usize;
        let mut out = self.last.unwrap_or_else(|| self.step());
        for _ in 0..n {
            out = self.step();
            f(self, &out);
        }
        out
    }

    /// Runs until `state` is reached or `timeout` seconds pass; the time it took.
    pub fn run_until(&mut self, state: State, timeout: f64) -> Option<f64> {
        let t0 = self.t;
        while self.t - t0 < timeout {
            let out = self.step();
            if out.state == state {
                return Some(self.t - t0);
            }
        }
        None
    }

    /// Angle error of the observer, wrapped, electrical degrees.
    pub fn angle_error_deg(&self, out: &TickOutput) -> f64 {
        wrap(f64::from(out.telemetry.estimate.theta_rad) - self.sample_theta).to_degrees()
    }
}

//! A deterministic synthetic run of the servo motor (`docs/design.md` section 6) at constant speed,
//! made on the target in `f32`.
//!
//! The plant is the exact solution of the alpha-beta current equations (`docs/design.md` section 2)
//! over one period for a voltage held by the inverter and a rotor turning at constant speed
//! (the derivation is in `ekf_core::observer`'s module docs). In complex notation
//! (`i = i_a + j i_b`, `p_k = e^{j th_k}`):
//!
//! ```text
//! i[k+1] = alpha i[k] + (1 - alpha) / Rs u[k] + E p_k,    E = -j c w G,
//! alpha = exp(-a Ts),  G = (e^{j w Ts} - alpha) / (a + j w),  a = Rs / Ls,  c = psi_f / Ls
//! ```
//!
//! `alpha`, `G` and the other per-run constants are computed at compile time in `f64`
//! (`const fn` series) and rounded to `f32`, so no `f64` arithmetic runs on the target. Per
//! sample, `p_k` is advanced by one multiplication by `e^{j w Ts}` (and renormalized), the voltage
//! is the steady-state voltage of a q-axis current `IQ_A` put through the inverse Park transform of
//! `foc`, and the sampled currents go to the phases and back through `foc`'s Clarke transform, as
//! on an MCU that measures phase currents, with a deterministic uniform noise of `+-NOISE_A` on
//! phases a and b.
//!
//! Timing follows `docs/design.md` section 4: `u[k]` is held over `[t_k, t_{k+1})`, `i[k]` is
//! sampled at `t_k`, and the observer's step `k` takes `(u[k-1], i[k])`.

use ekf_core::catalog::SERVO;
use ekf_core::wrap_angle;
use foc::{AlphaBeta, Dq};

/// Number of samples of the run (0.2 s at 10 kHz).
pub const SAMPLES: usize = 2000;

/// Sample period, s.
const TS: f64 = 1e-4;
/// Servo motor: stator resistance (ohm), inductance (H), flux linkage (Wb), pole pairs.
const RS: f64 = SERVO.rs_ohm;
const LS: f64 = SERVO.ld_h;
const PSI: f64 = SERVO.psi_f_wb;
const POLE_PAIRS: f64 = SERVO.pole_pairs as f64;
/// Mechanical speed of the run, rpm.
const SPEED_RPM: f64 = 1000.0;
/// Electrical speed, rad/s (418.9 rad/s: `w Ts` = 0.042 rad per sample).
const W: f64 = SPEED_RPM * core::f64::consts::TAU / 60.0 * POLE_PAIRS;
/// Rotor angle at `t_0`, rad electrical.
const TH0: f64 = 1.0;
/// q-axis current of the run, A.
const IQ_A: f64 = 2.0;
/// Half-width of the uniform current-sensor noise, A.
const NOISE_A: f32 = 0.02;

const A: f64 = RS / LS;
const C: f64 = PSI / LS;
const ALPHA: f64 = exp_series(-A * TS);
/// `e^{j w Ts}`.
const ROT: (f64, f64) = (cos_series(W * TS), sin_series(W * TS));
/// `G = (e^{j w Ts} - alpha) / (a + j w)`.
const G: (f64, f64) = cdiv((ROT.0 - ALPHA, ROT.1), (A, W));
/// `E = -j c w G`.
const E: (f64, f64) = (C * W * G.1, -C * W * G.0);
/// Input gain per sample `(1 - alpha) / Rs`, A/V.
const B: f64 = (1.0 - ALPHA) / RS;
/// Steady-state dq voltage of `i = j IQ_A e^{j th}`: `u = j e^{j th} ((Rs + j w Ls) IQ_A + w psi)`.
const U_D: f64 = -W * LS * IQ_A;
const U_Q: f64 = RS * IQ_A + W * PSI;
/// Steady-state current phasor `I0` of the discrete plant (`i[k] = I0 p_k`):
/// `I0 (e^{j w Ts} - alpha) = B U + E`.
const I0: (f64, f64) = cdiv((B * U_D + E.0, B * U_Q + E.1), (ROT.0 - ALPHA, ROT.1));

/// `p_0 = e^{j th_0}`.
const P0: (f64, f64) = (cos_series(TH0), sin_series(TH0));
/// `i[0] = I0 p_0`.
const I_START: (f64, f64) = (I0.0 * P0.0 - I0.1 * P0.1, I0.0 * P0.1 + I0.1 * P0.0);

/// The true electrical speed of the run, rad/s.
pub const OMEGA_E_RAD_S: f32 = W as f32;
/// The sample period, s.
pub const TS_S: f32 = TS as f32;

/// One sample: the voltage applied from `t_k`, the currents sampled at `t_k`, the true angle.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sample {
    /// `u[k] = [u_a, u_b]`, V, held over `[t_k, t_{k+1})`.
    pub u: [f32; 2],
    /// `i[k] = [i_a, i_b]`, A, sampled at `t_k` (with sensor noise).
    pub i: [f32; 2],
    /// True electrical angle at `t_k`, rad, in `[-pi, pi)`.
    pub theta_rad: f32,
}

/// Fills `out` with the run (module docs).
pub fn generate(out: &mut [Sample; SAMPLES]) {
    let rot = (ROT.0 as f32, ROT.1 as f32);
    let (e_re, e_im) = (E.0 as f32, E.1 as f32);
    let (alpha, b) = (ALPHA as f32, B as f32);
    let dq = Dq {
        d: U_D as f32,
        q: U_Q as f32,
    };
    let (mut p_re, mut p_im) = (P0.0 as f32, P0.1 as f32);
    let (mut i_re, mut i_im) = (I_START.0 as f32, I_START.1 as f32);
    let th0 = TH0 as f32;
    let mut rng = XorShift32(0x1234_5678);
    let w_ts = (W * TS) as f32;
    for (k, s) in out.iter_mut().enumerate() {
        // Phase currents measured with noise, back to alpha-beta as the MCU does.
        let mut abc = AlphaBeta {
            alpha: i_re,
            beta: i_im,
        }
        .to_abc();
        abc.a += rng.uniform(NOISE_A);
        abc.b += rng.uniform(NOISE_A);
        let i_meas = abc.to_alpha_beta();
        let u = dq.to_alpha_beta(p_im, p_re);
        *s = Sample {
            u: [u.alpha, u.beta],
            i: [i_meas.alpha, i_meas.beta],
            theta_rad: wrap_angle(th0 + k as f32 * w_ts),
        };
        // Exact plant step over [t_k, t_{k+1}).
        let (n_re, n_im) = (
            alpha * i_re + b * u.alpha + (e_re * p_re - e_im * p_im),
            alpha * i_im + b * u.beta + (e_re * p_im + e_im * p_re),
        );
        (i_re, i_im) = (n_re, n_im);
        // p_{k+1} = p_k e^{j w Ts}, pulled back to the unit circle (first-order correction).
        let (q_re, q_im) = (p_re * rot.0 - p_im * rot.1, p_re * rot.1 + p_im * rot.0);
        let g = 1.5 - 0.5 * (q_re * q_re + q_im * q_im);
        (p_re, p_im) = (q_re * g, q_im * g);
    }
}

/// Marsaglia's xorshift32: a deterministic noise source.
struct XorShift32(u32);

impl XorShift32 {
    /// Uniform in `[-half_width, half_width)`.
    fn uniform(&mut self, half_width: f32) -> f32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        let unit = (x >> 8) as f32 * (1.0 / 16_777_216.0); // [0, 1)
        (2.0 * unit - 1.0) * half_width
    }
}

/// `exp(x)` by its Taylor series (compile time only; `|x| < 1`).
const fn exp_series(x: f64) -> f64 {
    let (mut sum, mut term, mut n) = (1.0, 1.0, 1);
    while n < 30 {
        term = term * x / n as f64;
        sum += term;
        n += 1;
    }
    sum
}

/// `sin(x)` by its Taylor series (compile time only; `|x| <= 2`).
const fn sin_series(x: f64) -> f64 {
    let (mut sum, mut term, mut n) = (x, x, 1);
    while n < 20 {
        term = -term * x * x / ((2 * n) * (2 * n + 1)) as f64;
        sum += term;
        n += 1;
    }
    sum
}

/// `cos(x)` by its Taylor series (compile time only; `|x| <= 2`).
const fn cos_series(x: f64) -> f64 {
    let (mut sum, mut term, mut n) = (1.0, 1.0, 1);
    while n < 20 {
        term = -term * x * x / ((2 * n - 1) * (2 * n)) as f64;
        sum += term;
        n += 1;
    }
    sum
}

/// Complex division `n / d` (compile time only).
const fn cdiv(n: (f64, f64), d: (f64, f64)) -> (f64, f64) {
    let m = d.0 * d.0 + d.1 * d.1;
    ((n.0 * d.0 + n.1 * d.1) / m, (n.1 * d.0 - n.0 * d.1) / m)
}

//! The plant: a PMSM (surface or interior) with its mechanics.
//!
//! # Equations (SI, electrical quantities unless `_mech`)
//!
//! In the rotor (dq) frame, amplitude-invariant Park transform
//! (`i_d = i_a cos th + i_b sin th`, `i_q = -i_a sin th + i_b cos th`):
//!
//! ```text
//! Ld di_d/dt  = u_d - Rs i_d + w_e Lq i_q
//! Lq di_q/dt  = u_q - Rs i_q - w_e Ld i_d - w_e psi_f
//! Te          = 1.5 p (psi_f i_q + (Ld - Lq) i_d i_q)
//! J dw_mech/dt = Te - B w_mech - Tc sign(w_mech) - T_load
//! dth/dt      = w_e = p w_mech
//! ```
//!
//! With `Ld = Lq = Ls` this is the surface motor of docs/design.md, "The motor model". `T_load` is the
//! torque the load takes from the shaft (positive brakes positive rotation); `Tc` is the
//! Coulomb friction, with sticking: a shaft at rest stays at rest while
//! `|Te - T_load| <= Tc`, and a shaft that would cross zero speed within a period under a net
//! drive smaller than `Tc` stops at zero.
//!
//! # Integration ([`Plant::step`])
//!
//! The inverter holds the stator voltage `u_ab` constant in the stationary frame over each
//! period `[t_k, t_k + h)` (docs/design.md, "Conventions"), and the load torque is held too. One step:
//!
//! 1. **Speed for the period.** The mechanical acceleration at `t_k` gives the mid-period
//!    speed `w_m = w_e(t_k) + p a(t_k) h / 2`; the rotor turns at `w_m` over the period
//!    (`th(t) = th_k + w_m (t - t_k)`).
//! 2. **Electrical part, exactly.** For a constant speed the dq equations are linear with
//!    constant coefficients, `x' = A x + f + g(t)`, where the held stationary voltage becomes a
//!    rotating input `u_d + j u_q = (u_a + j u_b) e^{-j th(t)}`. The solution is the sum of
//!    the constant particular solution `x_c = -A^-1 f`, the sinusoidal one
//!    `x_s(t) = Re(X e^{-j w t})` with `X = -(A + j w I)^-1 G`, and the homogeneous part
//!    `e^{A t} (x_0 - x_c - x_s(0))`. `e^{A t}` is in closed form:
//!    `e^{m t} (C I + S (A - m I))` with `m = tr(A) / 2` and, for `d = ((Rs/Ld - Rs/Lq) / 2)^2
//!    - w^2`, `C = cos(sqrt(-d) t)`, `S = sin(sqrt(-d) t) / sqrt(-d)` (or `cosh`/`sinh` when
//!    `d > 0`, series near `d = 0`). No sub-steps: the electrical part is exact for the held
//!    voltage and the constant speed `w_m`.
//! 3. **Mechanics.** The mean torque over the period from the exact mean currents (the
//!    closed-form integral of the solution above; exact for a surface motor, the reluctance
//!    term's product averaged for linear variation), the viscous term implicit
//!    (`B (w_0 + w_1) / 2`), Coulomb friction as above.
//!
//! Errors are second order in the speed change over a period (the speed is the only thing
//! held that is not held in reality); a test holds a 1 s driven run to 0.1 % of a much finer
//! RK4 reference ([`Plant::step_rk4`]).
//!
//! The angle is kept wrapped to `[-pi, pi)`; its sine and cosine are cached for the frame
//! transforms.
//!
//! # Optional d-axis saturation ([`DSaturation`], off by default)
//!
//! A d current that adds to the magnet's flux saturates the d-axis iron: the incremental
//! inductance falls, `Ld,inc(i_d) = Ld (1 - k clamp(i_d / I_s, 0, 1))` (`k` the fraction lost
//! at `I_s`), and the d flux is its integral, `psi_d(i_d) = psi_f + Ld i_d` for `i_d <= 0`,
//! `psi_f + Ld (i_d - k i_d^2 / (2 I_s))` up to `I_s`, then straight on with slope
//! `Ld (1 - k)`. The equations become (q flux `Lq i_q`, unsaturated)
//!
//! ```text
//! Ld,inc(i_d) di_d/dt = u_d - Rs i_d + w_e Lq i_q
//! Lq di_q/dt          = u_q - Rs i_q - w_e psi_d(i_d)
//! Te                  = 1.5 p (psi_d(i_d) i_q - Lq i_d i_q)
//! ```
//!
//! identical to the linear model for `i_d <= 0` (MTPA and field weakening only use negative
//! `i_d`). With it set ([`Plant::set_d_saturation`]) the plant steps by RK4 with 8 sub-steps
//! (no closed form), Coulomb friction as in [`Plant::step_rk4`]. It is what a polarity test by
//! high-frequency injection (`foc::hfi`) senses; no scenario turns it on, only
//! [`RunOptions::d_saturation`](crate::sim::RunOptions::d_saturation).

//!
//! # Optional back-EMF harmonics ([`EmfHarmonics`], off by default)
//!
//! A real magnet's flux linkage is not a pure sine. The 5th and 7th harmonics of the phase
//! flux (the 3rd and its multiples cancel in a star winding with an isolated neutral) make
//! the magnet's flux in phase `a`
//!
//! ```text
//! psi_a = psi_f (cos th + k5 cos(5 th + phi5) + k7 cos(7 th + phi7))
//! ```
//!
//! (phases `b`, `c` at `th -+ 2 pi / 3`): `k5`, `k7` are fractions of `psi_f`, `phi5`, `phi7`
//! their phases. The 5th is a negative-sequence set and the 7th a positive one, so the space
//! vector is `psi_ab = psi_f (e^{j th} + k5 e^{-j(5 th + phi5)} + k7 e^{j(7 th + phi7)})`,
//! and in the rotor frame both appear at the 6th harmonic:
//!
//! ```text
//! psi_pm,dq(th) = psi_f (1 + k5 e^{-j a5} + k7 e^{j a7}),   a5 = 6 th + phi5, a7 = 6 th + phi7
//! ```
//!
//! Its motional EMF `e_dq = w_e (d psi_pm,dq / d th + j psi_pm,dq)` is
//!
//! ```text
//! e_d = -w_e psi_f (5 k5 sin a5 + 7 k7 sin a7)
//! e_q =  w_e psi_f (1 - 5 k5 cos a5 + 7 k7 cos a7)
//! ```
//!
//! (in the stationary frame `j w_e psi_f (e^{j th} - 5 k5 e^{-j(5 th + phi5)} + 7 k7
//! e^{j(7 th + phi7)})`: the EMF's 5th and 7th harmonics are `5 k5` and `7 k7` of its
//! fundamental). The equations become
//!
//! ```text
//! Ld di_d/dt = u_d - Rs i_d + w_e Lq i_q - e_d
//! Lq di_q/dt = u_q - Rs i_q - w_e Ld i_d - e_q
//! Te         = 1.5 p ((Ld - Lq) i_d i_q + (e_d i_d + e_q i_q) / w_e)
//! ```
//!
//! The torque is the power the EMF takes, `1.5 (e_d i_d + e_q i_q)`, over the mechanical
//! speed: the energy balance `1.5 u.i = 1.5 Rs |i|^2 + d/dt (0.75 (Ld i_d^2 + Lq i_q^2)) + Te
//! w_mech` holds at every instant (a unit test checks it), and `(e_d i_d + e_q i_q) / w_e`
//! needs no division (`e / w_e` is the bracket above). The torque ripple is at `6 w_e`.
//! With harmonics set ([`MotorModel::emf_harmonics`]) the plant steps by RK4 with
//! [`HARMONIC_SUBSTEPS`] sub-steps (the EMF turns at `6 w_e`; no closed form), Coulomb
//! friction as in [`Plant::step_rk4`]. [`Plant::emf_ab_v`] gives the open-circuit EMF.

use core::f64::consts::{PI, TAU};

use ekf_core::{MotorParams, wrap_angle};
use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::error::FieldError;
use crate::plant::frames::{inverse_park, park};
use saturation::Saturation;

mod motor;
pub mod saturation;
pub use motor::*;

/// State of the plant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PlantState {
    /// d-axis current, A.
    pub i_d_a: f64,
    /// q-axis current, A.
    pub i_q_a: f64,
    /// Mechanical rotor speed, rad/s.
    pub omega_mech_rad_s: f64,
    /// Electrical rotor angle, rad, in `[-pi, pi)`.
    pub theta_e_rad: f64,
}

/// The PMSM with its mechanics; one [`step`](Plant::step) per PWM period.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    motor: MotorModel,
    state: PlantState,
    /// `(sin th, cos th)` of the present angle.
    sc: (f64, f64),
    /// `e^{m h}` for the last `h` used, and that `h` (recomputed when `h` changes).
    decay: (f64, f64),
    /// Steps taken (to refresh `sc` exactly now and then).
    steps: u32,
    /// Rotor mechanically locked (fault injection): speed held at zero.
    locked: bool,
    /// Optional d-axis saturation (module docs); `None`: the linear model, exactly.
    d_saturation: Option<DSaturation>,
    /// The saturating motor's flux-current relation and its stator flux `(psi_d, psi_q)`,
    /// the state its step integrates (module [`saturation`]); `None`: the linear model.
    magnetics: Option<(Saturation, (f64, f64))>,
}

/// `(C, S)` of `e^{N t} = C I + S N` for a traceless 2 x 2 `N` with `N^2 = disc I`.
fn cosh_sinh(disc: f64, t: f64) -> (f64, f64) {
    let z = disc * t * t;
    if z.abs() < 1e-6 {
        // Taylor series, error below 1e-20 relative.
        let c = 1.0 + z * (0.5 + z * (1.0 / 24.0 + z / 720.0));
        let s = t * (1.0 + z * (1.0 / 6.0 + z * (1.0 / 120.0 + z / 5040.0)));
        (c, s)
    } else if z < 0.0 {
        let nu = (-disc).sqrt();
        let (s, c) = (nu * t).sin_cos();
        (c, s / nu)
    } else {
        let nu = disc.sqrt();
        ((nu * t).cosh(), (nu * t).sinh() / nu)
    }
}

/// Torque of the saturated model (module docs), N m.
fn sat_torque(m: &MotorModel, sat: &DSaturation, i_d: f64, i_q: f64) -> f64 {
    let psi_d = sat.psi_d_wb(m.ld_h, m.psi_f_wb, i_d);
    1.5 * m.p() * (psi_d * i_q - m.lq_h * i_d * i_q)
}

/// Coulomb friction torque at the mechanical speed `wm`: `coulomb_nm` against the motion,
/// zero at rest (the stiction at a sign change is handled by the integrator).
fn coulomb_nm(m: &MotorModel, wm: f64) -> f64 {
    if wm > 0.0 {
        m.coulomb_nm
    } else if wm < 0.0 {
        -m.coulomb_nm
    } else {
        0.0
    }
}

/// `d/dt [i_d, i_q, w_mech, th]` of the saturated model (module docs) at `[i_d, i_q, w_mech]`
/// with the rotor-frame voltage `[u_d, u_q]`; Coulomb friction as `Tc sign(w)`.
fn sat_derivative(
    m: &MotorModel,
    sat: &DSaturation,
    [id, iq, wm]: [f64; 3],
    [ud, uq]: [f64; 2],
    t_load_nm: f64,
) -> [f64; 4] {
    let we = m.p() * wm;
    let psi_d = sat.psi_d_wb(m.ld_h, m.psi_f_wb, id);
    let te = sat_torque(m, sat, id, iq);
    let fr = coulomb_nm(m, wm);
    [
        (ud - m.rs_ohm * id + we * m.lq_h * iq) / sat.ld_inc_h(m.ld_h, id),
        (uq - m.rs_ohm * iq - we * psi_d) / m.lq_h,
        (te - m.b_nm_s_rad * wm - fr - t_load_nm) / m.j_kg_m2,
        we,
    ]
}

/// Adds the back-EMF harmonics (module docs) to `d/dt [i_d, i_q, w_mech, th]`: `-e_d / Ld`,
/// `-e_q / Lq` (harmonic parts) and their torque `1.5 p (e_d i_d + e_q i_q) / w_e` over `J`.
/// With d-axis saturation the d equation divides by `Ld` (the harmonics' share; a small
/// error where `i_d > 0` saturates).
fn add_harmonics(m: &MotorModel, h: &EmfHarmonics, [id, iq, wm, th]: [f64; 4], d: &mut [f64; 4]) {
    let (ed, eq) = h.emf_per_speed(m.psi_f_wb, th);
    let we = m.p() * wm;
    d[0] -= we * ed / m.ld_h;
    d[1] -= we * eq / m.lq_h;
    d[2] += 1.5 * m.p() * (ed * id + eq * iq) / m.j_kg_m2;
}

/// Classic RK4 on a state `[.., .., .., th]` over `n` sub-steps of `h`, the angle (last) kept
/// in `[-pi, pi)` between sub-steps (no jump inside one).
fn rk4(x: &mut [f64; 4], h: f64, n: u32, mut deriv: impl FnMut(&[f64; 4]) -> [f64; 4]) {
    let add = |a: &[f64; 4], k: &[f64; 4], f: f64| -> [f64; 4] {
        [
            a[0] + f * k[0],
            a[1] + f * k[1],
            a[2] + f * k[2],
            a[3] + f * k[3],
        ]
    };
    for _ in 0..n {
        let k1 = deriv(x);
        let k2 = deriv(&add(x, &k1, 0.5 * h));
        let k3 = deriv(&add(x, &k2, 0.5 * h));
        let k4 = deriv(&add(x, &k3, h));
        for i in 0..4 {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if x[3] >= PI {
            x[3] -= TAU;
        } else if x[3] < -PI {
            x[3] += TAU;
        }
    }
}

/// Complex product `a b`, numbers as `(re, im)`.
#[inline]
fn cmul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

/// Complex quotient `a / b`.
#[inline]
fn cdiv(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let n = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / n, (a.1 * b.0 - a.0 * b.1) / n)
}

impl Plant {
    /// A plant at the given state (angle wrapped).
    pub fn new(motor: MotorModel, mut state: PlantState) -> Self {
        state.theta_e_rad = wrap_angle(state.theta_e_rad);
        let magnetics = motor.magnetics().map(|m| {
            let i = (state.i_d_a, state.i_q_a);
            let flux = m
                .flux(i, (motor.psi_f_wb, 0.0))
                .unwrap_or((motor.psi_f_wb + motor.ld_h * i.0, motor.lq_h * i.1));
            (m, flux)
        });
        Self {
            motor,
            state,
            sc: state.theta_e_rad.sin_cos(),
            decay: (1.0, 0.0),
            steps: 0,
            locked: false,
            d_saturation: None,
            magnetics,
        }
    }

    /// Turns the d-axis saturation model on (`Some`, module docs) or off. Refuses a `drop`
    /// outside `[0, 1)` or a non-positive `current_a` (returns `false`, nothing changed).
    pub fn set_d_saturation(&mut self, sat: Option<DSaturation>) -> bool {
        if let Some(s) = sat
            && (!((0.0..1.0).contains(&s.drop) && s.current_a > 0.0 && s.current_a.is_finite())
                || self.magnetics.is_some())
        {
            return false;
        }
        self.d_saturation = sat;
        true
    }

    /// Changes the stator resistance and the flux linkage (parameter drift, e.g. with
    /// temperature; module [`faults`](crate::plant::fault_injection)). Takes effect at the next step.
    /// A saturating motor takes the resistance only (its flux is its saturation model's).
    pub fn set_rs_psi(&mut self, rs_ohm: f64, psi_f_wb: f64) {
        self.motor.rs_ohm = rs_ohm;
        self.motor.psi_f_wb = psi_f_wb;
        // Recompute the cached decay factor at the next step.
        self.decay = (1.0, 0.0);
    }

    /// Locks the rotor mechanically (a jam): the speed becomes zero at once and stays zero
    /// while locked; the electrical part runs as usual. `false` frees it (from rest).
    pub fn set_locked(&mut self, locked: bool) {
        self.locked = locked;
        if locked {
            self.state.omega_mech_rad_s = 0.0;
        }
    }

    /// Whether the rotor is locked.
    pub fn is_locked(&self) -> bool {
        self.locked
    }

    /// Opens phase `phase` (0 a, 1 b, 2 c) for the state: removes the current component along
    /// that phase's axis, so that its phase current is zero. Called after every step while
    /// the phase is open, this is the open-phase motor (star, isolated neutral): the current
    /// vector is confined to the axis perpendicular to the open phase, and along it the
    /// decoupled alpha-beta equation of a surface motor is unchanged (the line voltage of
    /// the two remaining phases drives it). The step's torque is that of the unconstrained
    /// currents (an error of the order of one period's current build-up along the open axis).
    pub fn open_phase(&mut self, phase: usize) {
        let (ex, ey) = match phase {
            0 => (1.0, 0.0),
            1 => (-0.5, 0.5 * 3f64.sqrt()),
            _ => (-0.5, -0.5 * 3f64.sqrt()),
        };
        let [ia, ib] = self.i_ab_a();
        let along = ia * ex + ib * ey;
        let (ia, ib) = (ia - along * ex, ib - along * ey);
        let dq = park(DVec2::new(ia, ib), self.rot());
        self.state.i_d_a = dq.x;
        self.state.i_q_a = dq.y;
        self.refresh_flux();
    }

    /// The motor.
    pub fn motor(&self) -> &MotorModel {
        &self.motor
    }

    /// The present state.
    pub fn state(&self) -> PlantState {
        self.state
    }

    /// Electrical speed `p w_mech`, rad/s.
    pub fn omega_e_rad_s(&self) -> f64 {
        self.motor.p() * self.state.omega_mech_rad_s
    }

    /// `(sin th, cos th)` of the present electrical angle.
    pub fn sin_cos(&self) -> (f64, f64) {
        self.sc
    }

    /// The rotor direction `(cos th, sin th)` of the present electrical angle.
    pub fn rot(&self) -> DVec2 {
        let (s, c) = self.sc;
        DVec2::new(c, s)
    }

    /// Stator currents in the rotor frame `(i_d, i_q)`, A.
    pub fn i_dq_a(&self) -> DVec2 {
        DVec2::new(self.state.i_d_a, self.state.i_q_a)
    }

    /// Stator currents in the stationary frame `[i_alpha, i_beta]`, A.
    pub fn i_ab_a(&self) -> [f64; 2] {
        inverse_park(self.i_dq_a(), self.rot()).to_array()
    }

    /// Phase currents `[i_a, i_b, i_c]`, A (inverse amplitude-invariant Clarke).
    pub fn i_abc_a(&self) -> [f64; 3] {
        crate::plant::frames::inverse_clarke(self.i_ab_a())
    }

    /// Electromagnetic torque at the present state, N m.
    pub fn torque_nm(&self) -> f64 {
        let (id, iq) = (self.state.i_d_a, self.state.i_q_a);
        if let Some((_, (pd, pq))) = &self.magnetics {
            return 1.5 * self.motor.p() * (pd * iq - pq * id);
        }
        let te = match self.d_saturation {
            None => self.motor.torque_nm(id, iq),
            Some(sat) => sat_torque(&self.motor, &sat, id, iq),
        };
        let h = &self.motor.emf_harmonics;
        if h.is_on() {
            let (ed, eq) = h.emf_per_speed(self.motor.psi_f_wb, self.state.theta_e_rad);
            te + 1.5 * self.motor.p() * (ed * id + eq * iq)
        } else {
            te
        }
    }

    /// The motional back-EMF in the stationary frame at the present angle and speed,
    /// `[e_alpha, e_beta]`, V: `(e_d + j e_q) e^{j th}` with the harmonics (module docs), the
    /// terminal voltage of the open-circuited motor.
    pub fn emf_ab_v(&self) -> [f64; 2] {
        let m = &self.motor;
        let th = self.state.theta_e_rad;
        let (ed, eq) = if m.emf_harmonics.is_on() {
            m.emf_harmonics.emf_per_speed(m.psi_f_wb, th)
        } else {
            (0.0, 0.0)
        };
        let w = self.omega_e_rad_s();
        let e = DVec2::new(w * ed, w * (m.psi_f_wb + eq));
        inverse_park(e, self.rot()).to_array()
    }

    /// Net accelerating torque `Te - B w - friction - T_load` for a shaft at speed `wm` with
    /// driving torque `drive = Te - T_load` (Coulomb friction with sticking at rest).
    fn friction_nm(&self, wm: f64, drive: f64) -> f64 {
        let tc = self.motor.coulomb_nm;
        if wm > 0.0 {
            tc
        } else if wm < 0.0 {
            -tc
        } else if drive.abs() <= tc {
            drive // sticks: friction cancels the drive
        } else {
            tc * drive.signum()
        }
    }

    /// Advances by `h_s` with the stationary-frame stator voltage `u_ab_v` (V) and the load
    /// torque `t_load_nm` (N m) held constant (module docs give the method).
    pub fn step(&mut self, u_ab_v: [f64; 2], t_load_nm: f64, h_s: f64) {
        if self.magnetics.is_some() {
            self.step_saturated(u_ab_v, t_load_nm, h_s);
            return;
        }
        if self.d_saturation.is_some() || self.motor.emf_harmonics.is_on() {
            self.step_rk4(u_ab_v, t_load_nm, h_s, HARMONIC_SUBSTEPS);
            return;
        }
        let m = &self.motor;
        let p = m.p();
        let x = self.state;
        let (s0, c0) = self.sc;

        // 1. Speed for the period.
        let te0 = m.torque_nm(x.i_d_a, x.i_q_a);
        let drive0 = te0 - t_load_nm;
        let acc0 = (drive0
            - m.b_nm_s_rad * x.omega_mech_rad_s
            - self.friction_nm(x.omega_mech_rad_s, drive0))
            / m.j_kg_m2;
        let w = if self.locked {
            0.0
        } else {
            p * (x.omega_mech_rad_s + 0.5 * h_s * acc0)
        };

        // 2. Electrical part, exact for the held voltage and the constant speed w.
        let (ad, aq) = (m.rs_ohm / m.ld_h, m.rs_ohm / m.lq_h);
        let (ld, lq, psi) = (m.ld_h, m.lq_h, m.psi_f_wb);
        // Voltage in the frame at t_k: (u_a + j u_b) e^{-j th_k}.
        let uth: (f64, f64) = park(DVec2::from(u_ab_v), DVec2::new(c0, s0)).into();
        // Constant particular solution.
        let det = ad * aq + w * w;
        let xc = (-w * w * psi / (ld * det), -ad * w * psi / (lq * det));
        // Sinusoidal particular solution: X1 = -Uth (-aq + 2jw) / (Ld detM),
        // X2 = -Uth (2w + j ad) / (Lq detM), detM = ad aq - j w (ad + aq).
        let dm = (ad * aq, -w * (ad + aq));
        let x1 = cdiv(cmul(uth, (aq, -2.0 * w)), (ld * dm.0, ld * dm.1));
        let x2 = cdiv(cmul(uth, (-2.0 * w, -ad)), (lq * dm.0, lq * dm.1));
        // Homogeneous part.
        let y0 = (x.i_d_a - xc.0 - x1.0, x.i_q_a - xc.1 - x2.0);
        let half_diff = 0.5 * (ad - aq);
        let (sw, cw) = (w * h_s).sin_cos();
        let (cc, ss) = if half_diff == 0.0 {
            // Surface motor: the rotation is w itself; reuse its sine and cosine.
            if (w * h_s).abs() < 1e-4 {
                cosh_sinh(-w * w, h_s)
            } else {
                (cw, sw / w)
            }
        } else {
            cosh_sinh(half_diff * half_diff - w * w, h_s)
        };
        if self.decay.1 != h_s {
            self.decay = ((-0.5 * (ad + aq) * h_s).exp(), h_s);
        }
        let em = self.decay.0;
        let hy = (
            em * (cc * y0.0 + ss * (-half_diff * y0.0 + w * lq / ld * y0.1)),
            em * (cc * y0.1 + ss * (-w * ld / lq * y0.0 + half_diff * y0.1)),
        );
        // x_s(h) = Re(X e^{-j w h}).
        let rot = (cw, -sw);
        let id1 = hy.0 + xc.0 + cmul(x1, rot).0;
        let iq1 = hy.1 + xc.1 + cmul(x2, rot).0;

        // 3. Mechanics. Mean currents over the period, exactly: the integral of the
        // homogeneous part is A^-1 (e^{Ah} - I) y0, of the sinusoidal one Re(X E) with
        // E = int_0^h e^{-jwt} dt = (sin wh - j (1 - cos wh)) / w.
        let dy = (hy.0 - y0.0, hy.1 - y0.1);
        let int_h = (
            (-aq * dy.0 - w * lq / ld * dy.1) / det,
            (w * ld / lq * dy.0 - ad * dy.1) / det,
        );
        let x_wh = w * h_s;
        let e_int = if x_wh.abs() < 1e-2 {
            let x2 = x_wh * x_wh;
            (
                h_s * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0))),
                -h_s * x_wh * 0.5 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0)),
            )
        } else {
            (sw / w, -(1.0 - cw) / w)
        };
        let mean_d = (int_h.0 + cmul(x1, e_int).0) / h_s + xc.0;
        let mean_q = (int_h.1 + cmul(x2, e_int).0) / h_s + xc.1;
        // Mean torque: exact for a surface motor; the reluctance term's mean of a product
        // is taken for linear variation over the period (mean product + slope term / 12).
        let mean_dq = mean_d * mean_q + (id1 - x.i_d_a) * (iq1 - x.i_q_a) / 12.0;
        let te_mean = 1.5 * p * (m.psi_f_wb * mean_q + (m.ld_h - m.lq_h) * mean_dq);
        let w1 = if self.locked {
            0.0
        } else {
            self.mechanics(te_mean, t_load_nm, h_s)
        };

        let th1 = wrap_angle(x.theta_e_rad + w * h_s);
        self.state = PlantState {
            i_d_a: id1,
            i_q_a: iq1,
            omega_mech_rad_s: w1,
            theta_e_rad: th1,
        };
        // sin, cos of th1 = th0 + w h by the angle-addition formula (one trig call saved),
        // renormalized; recomputed from th1 every 1024 steps so that rounding cannot drift.
        self.steps = self.steps.wrapping_add(1);
        self.sc = if self.steps.is_multiple_of(1024) {
            th1.sin_cos()
        } else {
            let (s1, c1) = (s0 * cw + c0 * sw, c0 * cw - s0 * sw);
            let norm = 1.5 - 0.5 * (s1 * s1 + c1 * c1);
            (s1 * norm, c1 * norm)
        };
    }

    /// Mechanical speed at the end of a period with the mean electromagnetic torque
    /// `te_mean_nm` and the load `t_load_nm`: implicit viscous term, Coulomb friction with
    /// sticking.
    fn mechanics(&self, te_mean_nm: f64, t_load_nm: f64, h_s: f64) -> f64 {
        let m = &self.motor;
        let drive = te_mean_nm - t_load_nm;
        let k = 0.5 * h_s * m.b_nm_s_rad / m.j_kg_m2;
        let w0 = self.state.omega_mech_rad_s;
        let fr = self.friction_nm(w0, drive);
        let w1 = (w0 * (1.0 - k) + h_s / m.j_kg_m2 * (drive - fr)) / (1.0 + k);
        if m.coulomb_nm > 0.0 && (w0 != 0.0 && w1 * w0 < 0.0) && drive.abs() <= m.coulomb_nm {
            0.0 // would cross zero under a drive smaller than the friction: stops
        } else {
            w1
        }
    }

    /// Advances by `h_s` with the inverter off (all switches open): the stator currents are
    /// taken to decay to zero within the period through the free-wheeling diodes (mean torque
    /// half the initial one), then no current flows. Valid while the line-to-line back-EMF
    /// peak `sqrt(3) w_e psi_f` stays below the bus voltage; above it the diodes would
    /// rectify, which is not modelled.
    pub fn step_open(&mut self, t_load_nm: f64, h_s: f64) {
        let te_mean = 0.5 * self.torque_nm();
        let w0 = self.state.omega_mech_rad_s;
        let w1 = if self.locked {
            0.0
        } else {
            self.mechanics(te_mean, t_load_nm, h_s)
        };
        let th1 = wrap_angle(self.state.theta_e_rad + 0.5 * self.motor.p() * (w0 + w1) * h_s);
        self.state = PlantState {
            i_d_a: 0.0,
            i_q_a: 0.0,
            omega_mech_rad_s: w1,
            theta_e_rad: th1,
        };
        self.sc = th1.sin_cos();
        self.refresh_flux();
    }

    /// Reference integrator: classic RK4 on the dq equations over `substeps` equal sub-steps
    /// (at least one), the stationary voltage rotated into the dq frame at every stage and
    /// Coulomb friction as `Tc sign(w)` without sticking; the d-axis saturation and the
    /// back-EMF harmonics when set, a locked rotor held. The plant's own step with either
    /// model; otherwise slow, for tests.
    pub fn step_rk4(&mut self, u_ab_v: [f64; 2], t_load_nm: f64, h_s: f64, substeps: u32) {
        let n = substeps.max(1);
        let h = h_s / f64::from(n);
        let s = self.state;
        let mut x = [s.i_d_a, s.i_q_a, s.omega_mech_rad_s, s.theta_e_rad];
        let m = &self.motor;
        let sat = self.d_saturation;
        let locked = self.locked;
        let deriv = |x: &[f64; 4]| -> [f64; 4] {
            let [id, iq, wm, th] = *x;
            let (sn, cs) = th.sin_cos();
            let DVec2 { x: ud, y: uq } = park(DVec2::from(u_ab_v), DVec2::new(cs, sn));
            let mut d = if let Some(sat) = sat {
                sat_derivative(m, &sat, [id, iq, wm], [ud, uq], t_load_nm)
            } else {
                let we = m.p() * wm;
                let te = m.torque_nm(id, iq);
                let fr = coulomb_nm(m, wm);
                [
                    (ud - m.rs_ohm * id + we * m.lq_h * iq) / m.ld_h,
                    (uq - m.rs_ohm * iq - we * m.ld_h * id - we * m.psi_f_wb) / m.lq_h,
                    (te - m.b_nm_s_rad * wm - fr - t_load_nm) / m.j_kg_m2,
                    we,
                ]
            };
            let h = &m.emf_harmonics;
            if h.is_on() {
                add_harmonics(m, h, [id, iq, wm, th], &mut d);
            }
            if locked {
                d[2] = 0.0;
                d[3] = 0.0;
            }
            d
        };
        rk4(&mut x, h, n, deriv);
        self.state = PlantState {
            i_d_a: x[0],
            i_q_a: x[1],
            omega_mech_rad_s: x[2],
            theta_e_rad: wrap_angle(x[3]),
        };
        self.sc = self.state.theta_e_rad.sin_cos();
    }

    /// The d-axis saturation model in use, if any.
    pub fn d_saturation(&self) -> Option<DSaturation> {
        self.d_saturation
    }

    /// Whether every state variable is finite; else the name of the first that is not and
    /// its value.
    pub fn check_finite(&self) -> Result<(), (&'static str, f64)> {
        let s = &self.state;
        for (name, v) in [
            ("plant current i_d_a", s.i_d_a),
            ("plant current i_q_a", s.i_q_a),
            ("plant speed omega_mech_rad_s", s.omega_mech_rad_s),
            ("plant angle theta_e_rad", s.theta_e_rad),
        ] {
            if !v.is_finite() {
                return Err((name, v));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives a motor for `periods` periods of `ts` with a self-commutated voltage (`u_q` at
    /// the start-of-period angle plus some `u_d`), a load step at half time, and records the
    /// state after every period. `substeps == 0` selects the exact step.
    fn driven_run(
        motor: MotorModel,
        uq: f64,
        load: f64,
        periods: usize,
        ts: f64,
        substeps: u32,
    ) -> Vec<PlantState> {
        let mut plant = Plant::new(
            motor,
            PlantState {
                theta_e_rad: 0.7,
                ..PlantState::default()
            },
        );
        let mut out = Vec::with_capacity(periods);
        for k in 0..periods {
            let th = plant.state().theta_e_rad + 0.3;
            let (s, c) = th.sin_cos();
            let ud = -0.2 * uq;
            let u = inverse_park(DVec2::new(ud, uq), DVec2::new(c, s)).to_array();
            let tl = if k >= periods / 2 { load } else { 0.0 };
            if substeps == 0 {
                plant.step(u, tl, ts);
            } else {
                plant.step_rk4(u, tl, ts, substeps);
            }
            out.push(plant.state());
        }
        out
    }

    /// Largest deviation of `a` from the reference `r`, relative to the reference's range:
    /// `(currents, speed, angle / 2 pi)`.
    fn worst_relative(a: &[PlantState], r: &[PlantState]) -> (f64, f64, f64) {
        let range = |f: &dyn Fn(&PlantState) -> f64| {
            let (lo, hi) = r
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                    (l.min(v), h.max(v))
                });
            hi - lo
        };
        let i_range = range(&|s| s.i_d_a).max(range(&|s| s.i_q_a));
        let w_range = range(&|s| s.omega_mech_rad_s);
        let (mut di, mut dw, mut dth) = (0.0f64, 0.0f64, 0.0f64);
        for (x, y) in a.iter().zip(r) {
            di = di.max((x.i_d_a - y.i_d_a).abs().max((x.i_q_a - y.i_q_a).abs()));
            dw = dw.max((x.omega_mech_rad_s - y.omega_mech_rad_s).abs());
            dth = dth.max(wrap_angle(x.theta_e_rad - y.theta_e_rad).abs());
        }
        (di / i_range, dw / w_range, dth / TAU)
    }

    fn check_one_second(motor: MotorModel, uq: f64, load: f64) {
        // 1 s at 10 kHz; reference RK4 with 64 sub-steps per period (6.4 us).
        let ts = 1e-4;
        let n = 10_000;
        let exact = driven_run(motor.clone(), uq, load, n, ts, 0);
        let fine = driven_run(motor.clone(), uq, load, n, ts, 64);
        let w_max = fine
            .iter()
            .map(|s| s.omega_mech_rad_s.abs())
            .fold(0.0, f64::max);
        let i_max = fine.iter().map(|s| s.i_q_a.abs()).fold(0.0, f64::max);
        assert!(
            w_max > 50.0 && i_max > 1.0,
            "not driven: w {w_max}, i {i_max}"
        );
        let (di, dw, dth) = worst_relative(&exact, &fine);
        println!(
            "{motor:?}: worst relative error: current {di:.2e}, speed {dw:.2e}, angle {dth:.2e}"
        );
        assert!(
            di < 1e-3 && dw < 1e-3 && dth < 1e-3,
            "current {di:e}, speed {dw:e}, angle {dth:e}"
        );
    }

    #[test]
    fn exact_step_matches_a_fine_rk4_to_0p1_percent_over_one_second() {
        check_one_second(MotorModel::servo(), 60.0, 0.5);
        let mut ipm = MotorModel::servo();
        ipm.ld_h = 6e-3;
        ipm.lq_h = 14e-3;
        ipm.coulomb_nm = 0.05;
        check_one_second(ipm, 60.0, 0.5);
        check_one_second(MotorModel::industrial_2k2(), 200.0, 5.0);
    }

    #[test]
    fn rk4_reference_converges() {
        // The reference itself: 64 and 256 sub-steps agree far below 0.1 %.
        let m = MotorModel::servo();
        let a = driven_run(m.clone(), 60.0, 0.5, 3000, 1e-4, 64);
        let b = driven_run(m, 60.0, 0.5, 3000, 1e-4, 256);
        let (di, dw, dth) = worst_relative(&a, &b);
        assert!(
            di < 1e-7 && dw < 1e-7 && dth < 1e-7,
            "{di:e} {dw:e} {dth:e}"
        );
    }

    #[test]
    fn steady_states_are_exact() {
        // Locked rotor (huge inertia), held voltage: the current settles at u / Rs.
        let mut m = MotorModel::servo();
        m.j_kg_m2 = 1e30;
        let mut plant = Plant::new(m.clone(), PlantState::default());
        for _ in 0..2000 {
            plant.step([10.0, -5.0], 0.0, 1e-4);
        }
        let i = plant.i_ab_a();
        assert!(
            (i[0] - 10.0 / 2.875).abs() < 1e-9 && (i[1] + 5.0 / 2.875).abs() < 1e-9,
            "{i:?}"
        );

        // Spinning at a fixed speed, no voltage: i_d, i_q settle at the short-circuit current.
        let mut plant = Plant::new(
            m,
            PlantState {
                omega_mech_rad_s: 100.0,
                ..PlantState::default()
            },
        );
        for _ in 0..2000 {
            plant.step([0.0, 0.0], 0.0, 1e-4);
        }
        let s = plant.state();
        let (w, r, l, psi) = (400.0, 2.875, 8.5e-3, 0.175);
        let det = r * r + w * w * l * l;
        assert!((s.i_d_a + w * w * l * psi / det).abs() < 1e-9, "{s:?}");
        assert!((s.i_q_a + r * w * psi / det).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn d_saturation_lowers_ld_for_positive_i_d_only() {
        let m = MotorModel::industrial_ipm();
        let sat = DSaturation {
            drop: 0.2,
            current_a: 9.0,
        };
        assert_eq!(sat.ld_inc_h(m.ld_h, -5.0), m.ld_h);
        assert!((sat.ld_inc_h(m.ld_h, 4.5) - 0.9 * m.ld_h).abs() < 1e-15);
        assert!((sat.ld_inc_h(m.ld_h, 20.0) - 0.8 * m.ld_h).abs() < 1e-15);
        // The flux is the integral of the incremental inductance (continuous at I_s).
        let h = 1e-6;
        for i in [-3.0, 2.0, 8.0, 9.0 - 1e-3, 12.0] {
            let num = (sat.psi_d_wb(m.ld_h, m.psi_f_wb, i + h)
                - sat.psi_d_wb(m.ld_h, m.psi_f_wb, i - h))
                / (2.0 * h);
            assert!(
                (num - sat.ld_inc_h(m.ld_h, i)).abs() < 1e-6 * m.ld_h,
                "{i}: {num}"
            );
        }
        // Negative d current (MTPA): the same trajectory as the linear plant, to RK4's error.
        let x0 = PlantState {
            i_d_a: -1.0,
            i_q_a: 3.0,
            omega_mech_rad_s: 5.0,
            theta_e_rad: 0.4,
        };
        let mut lin = Plant::new(m.clone(), x0);
        let mut sp = Plant::new(m.clone(), x0);
        assert!(sp.set_d_saturation(Some(sat)));
        assert!(!sp.set_d_saturation(Some(DSaturation {
            drop: 1.0,
            current_a: 1.0
        })));
        for _ in 0..200 {
            // (u_d, u_q) = (-50, 30) V at the rotor's angle.
            let (s, c) = sp.state().theta_e_rad.sin_cos();
            let u = [-30.0 * s - 50.0 * c, 30.0 * c - 50.0 * s];
            lin.step(u, 0.5, 1e-4);
            sp.step(u, 0.5, 1e-4);
            assert!(lin.state().i_d_a < 0.0);
        }
        // The exact step holds the speed over a period, RK4 does not: agreement to the exact
        // step's own error (0.1 % over a second, `exact_step_matches_a_fine_rk4...`).
        let (a, b) = (lin.state(), sp.state());
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-3 * x.abs().max(y.abs()) + 1e-6;
        assert!(
            close(a.i_d_a, b.i_d_a) && close(a.i_q_a, b.i_q_a),
            "{a:?} {b:?}"
        );
        assert!(close(a.omega_mech_rad_s, b.omega_mech_rad_s), "{a:?} {b:?}");
        // A positive d step at standstill: the current rises faster than on the linear plant.
        let x0 = PlantState::default();
        let (mut lin, mut sp) = (Plant::new(m.clone(), x0), Plant::new(m, x0));
        sp.set_d_saturation(Some(sat));
        for _ in 0..100 {
            lin.step([100.0, 0.0], 0.0, 1e-4);
            sp.step([100.0, 0.0], 0.0, 1e-4);
        }
        assert!(
            sp.state().i_d_a > 1.02 * lin.state().i_d_a,
            "{:?}",
            sp.state()
        );
    }

    #[test]
    fn emf_harmonics_keep_the_energy_balance() {
        // 1.5 u.i = 1.5 Rs |i|^2 + d/dt(0.75 (Ld i_d^2 + Lq i_q^2)) + Te w_mech at any state,
        // with the harmonics' EMF in the current equations and their torque in the mechanics.
        let mut m = MotorModel::industrial_ipm();
        m.b_nm_s_rad = 0.0;
        m.emf_harmonics = EmfHarmonics {
            h5: 0.03,
            h5_phase_rad: 0.7,
            h7: 0.02,
            h7_phase_rad: -2.0,
        };
        for (k, &(id, iq, wm, th, ud, uq)) in [
            (-1.0, 3.0, 80.0, 0.3, -40.0, 150.0),
            (0.5, -2.0, -30.0, 2.9, 20.0, -60.0),
            (2.0, 1.0, 150.0, -1.7, 5.0, 200.0),
        ]
        .iter()
        .enumerate()
        {
            let mut d = [
                (ud - m.rs_ohm * id + m.p() * wm * m.lq_h * iq) / m.ld_h,
                (uq - m.rs_ohm * iq - m.p() * wm * (m.ld_h * id + m.psi_f_wb)) / m.lq_h,
                m.torque_nm(id, iq) / m.j_kg_m2,
                m.p() * wm,
            ];
            add_harmonics(&m, &m.emf_harmonics, [id, iq, wm, th], &mut d);
            let te = d[2] * m.j_kg_m2;
            let p_in = 1.5 * (ud * id + uq * iq);
            let p_out = 1.5 * m.rs_ohm * (id * id + iq * iq)
                + 1.5 * (m.ld_h * id * d[0] + m.lq_h * iq * d[1])
                + te * wm;
            assert!(
                (p_in - p_out).abs() < 1e-9 * p_in.abs(),
                "{k}: {p_in} {p_out}"
            );
            // The plant's torque at that state is the same.
            let plant = Plant::new(
                m.clone(),
                PlantState {
                    i_d_a: id,
                    i_q_a: iq,
                    omega_mech_rad_s: wm,
                    theta_e_rad: th,
                },
            );
            assert!((plant.torque_nm() - te).abs() < 1e-12 * te.abs().max(1.0));
        }
        // The RK4 step of the plant with harmonics agrees with a much finer one.
        let a = driven_run(m.clone(), 200.0, 3.0, 2000, 1e-4, 0);
        let b = driven_run(m, 200.0, 3.0, 2000, 1e-4, 64);
        let (di, dw, dth) = worst_relative(&a, &b);
        assert!(
            di < 1e-5 && dw < 1e-5 && dth < 1e-5,
            "{di:e} {dw:e} {dth:e}"
        );
    }

    #[test]
    fn coulomb_friction_holds_and_stops_the_shaft() {
        let mut m = MotorModel::servo();
        m.coulomb_nm = 0.2;
        // At rest, a load of 0.1 N m does not move it.
        let mut plant = Plant::new(m.clone(), PlantState::default());
        for _ in 0..1000 {
            plant.step([0.0, 0.0], 0.1, 1e-4);
        }
        assert_eq!(plant.state().omega_mech_rad_s, 0.0);
        // Spinning freely, it coasts down to exactly zero and stays there.
        let mut plant = Plant::new(
            m,
            PlantState {
                omega_mech_rad_s: 5.0,
                ..PlantState::default()
            },
        );
        for _ in 0..1000 {
            plant.step([0.0, 0.0], 0.0, 1e-4);
        }
        assert_eq!(plant.state().omega_mech_rad_s, 0.0);
    }

    #[test]
    fn open_inverter_lets_the_shaft_coast() {
        let mut plant = Plant::new(
            MotorModel::servo(),
            PlantState {
                i_q_a: 2.0,
                omega_mech_rad_s: 100.0,
                ..PlantState::default()
            },
        );
        plant.step_open(0.0, 1e-4);
        let s = plant.state();
        assert_eq!((s.i_d_a, s.i_q_a), (0.0, 0.0));
        // Half of 2.1 N m, less 0.1 N m of friction, for 100 us on 8e-4 kg m^2: +0.11875 rad/s.
        assert!((s.omega_mech_rad_s - 100.11875).abs() < 1e-4, "{s:?}");
        for _ in 0..10_000 {
            plant.step_open(0.0, 1e-4);
        }
        // Viscous friction only: w = w_0 e^{-B t / J} after 1 s.
        let w = plant.state().omega_mech_rad_s;
        assert!((w - 100.11875 * (-1.25f64).exp()).abs() < 1e-4, "{w}");
    }

    #[test]
    fn positive_q_current_turns_the_rotor_forward_and_the_angle_stays_wrapped() {
        let run = driven_run(MotorModel::servo(), 60.0, 0.0, 2000, 1e-4, 0);
        assert!(run.iter().all(|s| (-PI..PI).contains(&s.theta_e_rad)));
        assert!(run[run.len() - 1].omega_mech_rad_s > 50.0);
    }

    #[test]
    fn reference_motors_validate() {
        for m in [
            MotorModel::servo(),
            MotorModel::industrial_2k2(),
            MotorModel::small_fast(),
            MotorModel::industrial_ipm(),
            MotorModel::traction_ipm(),
        ] {
            assert_eq!(m.validate(), Ok(()));
            assert_eq!(m.params().validate(), Ok(()));
        }
        let mut m = MotorModel::servo();
        m.ld_h = -1e-3;
        let e = m.validate().err();
        assert_eq!(e.map(|e| e.field), Some("motor.ld_h".to_string()));
    }

    #[test]
    fn interior_presets_match_ekf_core_and_rated_points_are_feasible() {
        use ekf_core::MotorParams;
        for (m, e) in [
            (
                MotorModel::industrial_ipm(),
                MotorParams::<f64>::industrial_ipm(),
            ),
            (
                MotorModel::traction_ipm(),
                MotorParams::<f64>::traction_ipm(),
            ),
        ] {
            assert_eq!(
                (m.rs_ohm, m.ld_h, m.lq_h, m.psi_f_wb, m.pole_pairs),
                (e.rs_ohm, e.ld_h, e.lq_h, e.psi_f_wb, e.pole_pairs)
            );
        }
        // (motor, bus V, rated rpm, rated torque, |i| at MTPA, i_d, |u| at rated, base rpm):
        // the numbers of the README's reference-motor table.
        let cases = [
            (
                MotorModel::servo(),
                300.0,
                2000.0,
                1.5,
                1.4286,
                0.0,
                151.1,
                2301.0,
            ),
            (
                MotorModel::industrial_2k2(),
                540.0,
                1500.0,
                10.0,
                4.077,
                0.0,
                280.2,
                1678.0,
            ),
            (
                MotorModel::small_fast(),
                48.0,
                3429.0,
                0.4,
                6.349,
                0.0,
                16.0,
                6054.0,
            ),
            (
                MotorModel::industrial_ipm(),
                540.0,
                1500.0,
                14.0,
                6.157,
                -0.874,
                274.7,
                1719.0,
            ),
            (
                MotorModel::traction_ipm(),
                48.0,
                3000.0,
                15.0,
                148.40,
                -79.14,
                26.72,
                3116.0,
            ),
        ];
        for (m, u_dc, rpm, torque, i_mag, i_d, u_rated, base) in cases {
            let (id, iq, i) = m.mtpa_currents_for_torque(torque);
            assert!((m.torque_nm(id, iq) - torque).abs() < 1e-9 * torque);
            assert!((i - i_mag).abs() < 1e-3 * i_mag, "{i}");
            assert!((id - i_d).abs() <= 1e-3 * i_d.abs(), "{id}");
            let dl = m.lq_h - m.ld_h;
            if dl > 0.0 {
                // The textbook form of the MTPA law gives the same i_d.
                let psi = m.psi_f_wb;
                let textbook = (psi - (psi * psi + 8.0 * dl * dl * i * i).sqrt()) / (4.0 * dl);
                assert!((id - textbook).abs() < 1e-9 * i, "{id} {textbook}");
            }
            // MTPA: no other split of |i| gives more torque.
            for k in -20..=20 {
                let d = id + 0.01 * f64::from(k) * i;
                if d.abs() < i {
                    let q = (i * i - d * d).sqrt();
                    assert!(m.torque_nm(d, q) <= torque * (1.0 + 1e-9), "{d}");
                }
            }
            let w_e = rpm / 30.0 * PI * m.p();
            let u = m.steady_voltage_v(id, iq, w_e);
            assert!((u - u_rated).abs() < 0.01 * u_rated, "{u}");
            assert!(
                u < u_dc / 3f64.sqrt(),
                "rated point above the voltage limit: {u}"
            );
            let b = m.base_speed_rpm(torque, u_dc);
            assert!((b - base).abs() < 1.0 && b > rpm, "base speed {b}");
        }
        // Surface motors: MTPA is i_d = 0.
        assert_eq!(MotorModel::servo().mtpa_i_d_a(3.0), 0.0);
    }
}

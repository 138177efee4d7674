//! The flux integral and the rotor's motion, once per tick (module docs of `saturation`).

use crate::trig::sin_cos;

use super::SaturationProbe;

impl SaturationProbe {
    /// The flux integral over the interval that just ended, in the fixed frame at the
    /// alignment angle (`i_f`: this tick's currents there, A), then the rotor's motion.
    ///
    /// `psi[k] = psi[k-1] + Ts (u[k-1-d] - e(i[k-1]) - Rs i_mean)`, `i_mean` the mean
    /// current over the interval by [`mean_current`], `e` the inverter's voltage error at
    /// the currents of the interval's start (module docs).
    pub(super) fn integrate(&mut self, i_f: [f32; 2]) {
        let ts = self.cfg.ts_s;
        if self.running {
            let u = self.u_hist[self.d];
            let rs = self.cfg.rs_ohm;
            let [i0, i1] = self.i_fix_hist;
            let e = self.inverter_error(self.ab(i1[0], i1[1]));
            // Predictor: the trapezoidal rule's flux at this tick.
            let pred =
                [0, 1].map(|x| self.psi[x] + ts * (u[x] - e[x] - rs * 0.5 * (i1[x] + i_f[x])));
            let i_mean = mean_current([self.psi_fix_prev, self.psi, pred], [i0, i1, i_f]);
            let psi = [0, 1].map(|x| self.psi[x] + ts * (u[x] - e[x] - rs * i_mean[x]));
            self.psi_fix_prev = self.psi;
            self.psi = psi;
        }
        self.i_fix_hist = [self.i_fix_hist[1], i_f];
        // The rotor's motion from the torque (frame-independent cross product).
        if self.cfg.inertia_kg_m2 > 0.0 {
            let p = self.cfg.pole_pairs as f32;
            let t = 1.5 * p * (self.psi[0] * i_f[1] - self.psi[1] * i_f[0]);
            // Trapezoidal in both integrals (the torque changes by its whole size within a
            // q pulse's few tens of ticks: a one-sided rule would misplace the rotor by a
            // few per cent of its motion within the pulse).
            let w0 = self.rotor_speed;
            self.rotor_speed += ts * p * 0.5 * (t + self.torque_prev) / self.cfg.inertia_kg_m2;
            self.torque_prev = t;
            self.rotor_angle += ts * 0.5 * (w0 + self.rotor_speed);
            self.rsc = sin_cos(self.rotor_angle);
            self.out.rotor_angle_max_rad = self.out.rotor_angle_max_rad.max(self.rotor_angle.abs());
        }
    }
}

/// The mean of each current over the last interval, from the fluxes `psi` and currents `i`
/// of the last three ticks (`[2]` this one; both fixed-frame axes).
///
/// At standstill the current is a static function of the flux, `i = f(psi)`, smooth where
/// the voltage steps (unlike `i(t)`), and the flux moves nearly linearly in time within a
/// tick (the voltage held, the resistive drop small beside it). So the mean current over the
/// interval is the mean of the parabola through the three `(psi, i)` points over the
/// interval's flux span `[psi1, psi2]`: the trapezoidal mean minus `(psi2 - psi1)^2 d012 / 6`,
/// `d012` the second divided difference of `i` in the flux (the axis whose flux moved most).
/// Where a pulse saturates the motor the current curves within a tick (its rise per tick
/// more than doubles over a few ticks); the trapezoidal rule alone then overstates the
/// resistive drop, by 0.2 mWb over a q lobe of the interior PM motor at 1.7 times its rated
/// current. Used only when the three fluxes are apart (every separation at least a quarter of
/// the largest), the correction at most half the interval's change of current (the mean of
/// a monotonic current lies within it); else the trapezoidal mean.
pub(super) fn mean_current(psi: [[f32; 2]; 3], i: [[f32; 2]; 3]) -> [f32; 2] {
    let trap = [0, 1].map(|x| 0.5 * (i[1][x] + i[2][x]));
    let span = |x: usize| (psi[2][x] - psi[1][x]).abs();
    let a = if span(0) >= span(1) { 0 } else { 1 };
    let [p0, p1, p2] = [psi[0][a], psi[1][a], psi[2][a]];
    let (h01, h12, h02) = (p1 - p0, p2 - p1, p2 - p0);
    let largest = h01.abs().max(h12.abs()).max(h02.abs());
    let smallest = h01.abs().min(h12.abs()).min(h02.abs());
    if !(largest > 0.0 && smallest >= 0.25 * largest) {
        return trap;
    }
    [0, 1].map(|x| {
        let d01 = (i[1][x] - i[0][x]) / h01;
        let d12 = (i[2][x] - i[1][x]) / h12;
        let d012 = (d12 - d01) / h02;
        let bound = 0.5 * (i[2][x] - i[1][x]).abs();
        trap[x] - (h12 * h12 * d012 / 6.0).clamp(-bound, bound)
    })
}

"""Makes the PM-SyRM fixture: a closed-loop motulator trace of the saturated 5.6 kW PM-SyRM
(pm_syrm_machine.py), for crates/pyfoc/tests/test_third_party_pm_syrm.py.

Plant: motulator.drive.model.SynchronousMachine with SaturatedSynchronousMachinePars(
n_p=2, R_s=0.63, i_s_dq_fcn=SaturationModelPMSyRM(...)) (algebraic current map), J = 0.05 kg m^2,
540 V inverter (VoltageSourceConverter), no PWM (zero-order hold of the duty-cycle-averaged
voltage), one-sampling-period computational delay (Drive default, delay=1).
Control: motulator.drive.control.sm VectorControlSystem with a sensored CurrentVectorController
(measured rotor angle/speed; flux-map-based current controller + MTPA/limits reference generator
using the same saturation model inverted into a flux map) and a 2DOF PI SpeedController.

Recorded at each sampling instant t_k = k*Ts (a wrapper around the control system, called by the
simulator at t_k before the new switching state is set):
  currents i_ab(t_k), true electrical angle theta_m(t_k) (machine state) and electrical speed
  n_p*w_M(t_k); the applied voltage row k = converter output voltage held over [t_k, t_k+1),
  read at the next call (t_{k+1}), before the gate signals are changed.
"""
import argparse, math, sys, time
from importlib.metadata import version
import numpy as np
import motulator.drive.control.sm as control
from motulator.common.model import SolverCfg
from motulator.drive import model, utils
from pm_syrm_machine import N_P, R_S, NOM, BASE, CURRENT_MAP, incremental_L, psi_f, psi_of_i

TS = 125e-6
T_STOP = 3.6
J = 0.05
W_HALF = 0.5 * BASE.w_M  # 50 % of rated mechanical speed (rated 1800 rpm -> 900 rpm)
TAU = NOM.tau             # rated torque 29.7 N m


def speed_ref(t):
    if t < 0.1:
        return 0.0
    if t < 0.6:
        return W_HALF * (t - 0.1) / 0.5
    if t < 2.5:
        return W_HALF
    if t < 3.1:
        return W_HALF * (1 - 2 * (t - 2.5) / 0.6)
    return -W_HALF


def load_torque(t):
    if t < 0.9:
        return 0.0
    if t < 1.4:
        return TAU          # rated-torque step
    if t < 1.9:
        return 1.5 * TAU    # 150 %
    if t < 2.3:
        return -TAU         # generating
    return TAU              # rated load held through the reversal (active load)


class Recorder:
    def __init__(self, inner):
        self.inner = inner
        self.rows = []   # [t, i_a, i_b, theta_e, w_e, load]
        self.u = []      # applied voltage of the previous period

    def get_enable(self):
        return self.inner.get_enable()

    def __call__(self, mdl):
        k = len(self.rows)
        if k > 0:  # the switching state held over [t_{k-1}, t_k) is still set
            self.u.append(complex(mdl.converter.out.u_c_ab))
        i_ab = complex(mdl.machine.out.i_s_ab)
        theta = float(np.real(mdl.machine.state.theta_m))
        w_e = N_P * float(mdl.mechanics.out.w_M)
        self.rows.append((mdl.t0, i_ab.real, i_ab.imag, theta, w_e, load_torque(mdl.t0)))
        return self.inner(mdl)

    def post_process(self):
        return self.inner.post_process()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="pm_syrm_trace.npz")
    args = ap.parse_args()
    par = model.SaturatedSynchronousMachinePars(n_p=N_P, R_s=R_S, i_s_dq_fcn=CURRENT_MAP)
    mdl = model.Drive(model.SynchronousMachine(par), model.MechanicalSystem(J=J),
                      model.VoltageSourceConverter(u_dc=540), pwm=False)
    mdl.mechanics.set_external_load_torque(load_torque)

    est_map = CURRENT_MAP.as_magnetic_model(
        d_range=np.linspace(-0.1 * BASE.psi, BASE.psi, 256),
        q_range=np.linspace(-1.4 * BASE.psi, 1.4 * BASE.psi, 256))
    est_par = control.SaturatedSynchronousMachinePars(n_p=N_P, R_s=R_S, psi_s_dq_fcn=est_map.invert())
    cfg = control.CurrentVectorControllerCfg(i_s_max=2 * BASE.i, sensorless=False, T_s=TS)
    inner = control.VectorControlSystem(
        control.CurrentVectorController(est_par, cfg),
        control.SpeedController(J=J, alpha_s=2 * math.pi * 4, tau_M_max=2 * TAU))
    inner.set_speed_ref(speed_ref)
    rec = Recorder(inner)
    t0 = time.time()
    res = model.Simulation(mdl, rec, show_progress=False).simulate(t_stop=T_STOP - TS / 2)
    print(f"simulated in {time.time()-t0:.1f} s, success={res.success}")
    if not res.success:
        return 1
    n = len(rec.u)  # last row has no completed period -> dropped
    rows = rec.rows[:n]
    r = np.array(rows)
    u = np.array(rec.u)
    # The motor as a commissioning at low current would give it, and the map itself on a grid.
    pf = psi_f()
    l0 = incremental_L(0j)
    i_d = np.linspace(-25.0, 10.0, 29)
    i_q = np.linspace(-25.0, 25.0, 31)
    psi = np.array([[psi_of_i(complex(a, b)) for b in i_q] for a in i_d])
    np.savez_compressed(
        args.out, ts=TS, rs=R_S, pole_pairs=N_P, psi_f=pf, ld0=l0[0, 0], lq0=l0[1, 1],
        u_ab=np.column_stack([u.real, u.imag]).astype(np.float32),
        i_ab=r[:, 1:3].astype(np.float32), theta_e=r[:, 3].astype(np.float32),
        omega_e=r[:, 4].astype(np.float32), load_torque=r[:, 5].astype(np.float32),
        map_i_d=i_d, map_i_q=i_q, map_psi_d=psi.real, map_psi_q=psi.imag,
        made_by=f"gen_pm_syrm_trace.py, motulator {version('motulator')}")
    print(f"{n} samples -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

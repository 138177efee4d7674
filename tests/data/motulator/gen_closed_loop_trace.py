"""Closed-loop runs of surface PMSMs under motulator's own sensored vector control: the fixtures
`startup_trace.npz`, `reversal_trace.npz` and `small_fast_trace.npz` for
`crates/pyfoc/tests/test_third_party_closed_loop.py`.

Plant: motulator.drive.model.SynchronousMachine (Ld = Lq) + MechanicalSystem(J, B_L),
VoltageSourceConverter on a constant DC bus, no PWM (zero-order hold of the duty-ratio-averaged
voltage, no dead time), one sampling period of computational delay (motulator's default).
Control: motulator's VectorControlSystem with a sensored CurrentVectorController (i_d = 0 for
Ld = Lq) and its 2DOF PI SpeedController, 10 kHz. Runs (`spec`): `startup`, the 2.2 kW motor
to 50 % of rated speed with the rated load (10 N m) from 0.6 s; `reversal`, the same motor at
+12 % of rated speed, the rated load from 0.3 s, the speed reference ramped to -12 % between
0.6 and 0.8 s (the drive generates after the zero crossing), 1.5 s; `small_fast`, the small
fast motor to 50 % of rated speed with its rated load (0.4 N m) from 0.6 s.

A wrapper around the control system is called at every sampling instant t_k = k Ts before the
new switching state is set: it records the machine at t_k (currents, electrical angle,
mechanical speed), sets the load torque held over [t_k, t_k+1), and reads the converter voltage
applied over [t_{k-1}, t_k). Row k holds the voltage applied over [t_k, t_k+1) and the machine
at t_k, as in `motulator_trace.csv`. Stored as float32.

Usage (Python >= 3.12 with the versions of requirements.txt):
    python gen_closed_loop_trace.py {startup,reversal,small_fast} [--out FILE]
"""

import argparse
import math
import sys
import time
from dataclasses import dataclass
from importlib.metadata import version

import numpy as np

import motulator.drive.control.sm as control
from motulator.common.model import SolverCfg
from motulator.common.utils import abc2complex
from motulator.drive import model


@dataclass
class Spec:
    name: str
    n_p: int
    R_s: float
    L_s: float
    psi_f: float
    J: float
    B: float
    u_dc: float
    rpm_rated: float
    tau_rated: float
    ts: float
    t_stop: float
    alpha_s: float  # speed-control bandwidth, rad/s
    alpha_c: float  # current-control bandwidth, rad/s
    speed_ref: object  # t -> mechanical rad/s
    load: object  # t -> N m (sampled at t_k, held over the period)

    @property
    def w_M_rated(self):
        return self.rpm_rated * 2 * math.pi / 60


def ramp(t, t0, t1, y0, y1):
    if t <= t0:
        return y0
    if t >= t1:
        return y1
    return y0 + (y1 - y0) * (t - t0) / (t1 - t0)


def spec(name: str) -> Spec:
    """The runs: `startup` and `reversal` on the 2.2 kW motor of docs/design.md (surface
    variant), `small_fast` on the small fast (drone class) motor."""
    if name in ("startup", "reversal"):
        w_r = 1500 * 2 * math.pi / 60
        base = dict(n_p=3, R_s=3.6, L_s=0.036, psi_f=0.545, J=0.015, B=1e-3, u_dc=540.0,
                    rpm_rated=1500.0, tau_rated=10.0, ts=1e-4,
                    alpha_s=2 * math.pi * 4, alpha_c=2 * math.pi * 200)
        if name == "startup":
            # To 50 % of rated speed in 0.3 s, the rated load from 0.6 s, 1 s.
            return Spec(name, **base, t_stop=1.0,
                        speed_ref=lambda t: ramp(t, 0.0, 0.3, 0.0, 0.5 * w_r),
                        load=lambda t: 10.0 if t >= 0.6 - 1e-9 else 0.0)
        # +12 % in 0.15 s, the rated load from 0.3 s, reversed to -12 % between 0.6 and 0.8 s.
        return Spec(name, **base, t_stop=1.5,
                    speed_ref=lambda t: ramp(t, 0.0, 0.15, 0.0, 0.12 * w_r) if t < 0.6
                    else ramp(t, 0.6, 0.8, 0.12 * w_r, -0.12 * w_r),
                    load=lambda t: 10.0 if t >= 0.3 - 1e-9 else 0.0)
    if name == "small_fast":
        # To 50 % of rated speed in 0.3 s, the rated load from 0.6 s, 1 s.
        w_r = 3429 * 2 * math.pi / 60
        return Spec(name, n_p=7, R_s=0.12, L_s=0.15e-3, psi_f=6e-3, J=2e-5, B=1e-6, u_dc=48.0,
                    rpm_rated=3429.0, tau_rated=0.4, ts=1e-4, t_stop=1.0,
                    alpha_s=2 * math.pi * 40, alpha_c=2 * math.pi * 400,
                    speed_ref=lambda t: ramp(t, 0.0, 0.3, 0.0, 0.5 * w_r),
                    load=lambda t: 0.4 if t >= 0.6 - 1e-9 else 0.0)
    raise ValueError(name)


class Recorder:
    """Wraps motulator's control system; logs the machine and the applied voltage."""

    def __init__(self, inner, sp: Spec):
        self.inner = inner
        self.sp = sp
        self.rows = []  # k, t, load, i_a, i_b, w_M, theta_e
        self.u = []  # voltage applied over [t_{k-1}, t_k), read at t_k

    def get_enable(self):
        return self.inner.get_enable()

    def __call__(self, mdl):
        k = len(self.rows)
        t = k * self.sp.ts
        if k > 0:
            self.u.append(complex(mdl.converter.out.u_c_ab))
        i_ab = complex(mdl.machine.out.i_s_ab)
        theta = float(np.real(mdl.machine.state.theta_m))
        w_M = float(mdl.mechanics.out.w_M)
        load = float(self.sp.load(t))
        mdl.mechanics.set_external_load_torque(load)  # held over [t_k, t_k+1)
        self.rows.append((k, t, load, i_ab.real, i_ab.imag, w_M, theta))
        return self.inner(mdl)

    def post_process(self):
        return self.inner.post_process()


def simulate(sp: Spec):
    par = model.SynchronousMachinePars(n_p=sp.n_p, R_s=sp.R_s, L_d=sp.L_s, L_q=sp.L_s,
                                       psi_f=sp.psi_f)
    mdl = model.Drive(model.SynchronousMachine(par), model.MechanicalSystem(J=sp.J, B_L=sp.B),
                      model.VoltageSourceConverter(u_dc=sp.u_dc), pwm=False)
    i_rated = sp.tau_rated / (1.5 * sp.n_p * sp.psi_f)
    cfg = control.CurrentVectorControllerCfg(i_s_max=2 * i_rated, sensorless=False, T_s=sp.ts,
                                             alpha_c=sp.alpha_c)
    inner = control.VectorControlSystem(
        control.CurrentVectorController(par, cfg),
        control.SpeedController(J=sp.J, alpha_s=sp.alpha_s, tau_M_max=2 * sp.tau_rated))
    inner.set_speed_ref(sp.speed_ref)
    rec = Recorder(inner, sp)
    t0 = time.time()
    res = model.Simulation(mdl, rec, show_progress=False,
                           cfg=SolverCfg(rtol=1e-9, atol=1e-9)).simulate(t_stop=sp.t_stop + sp.ts / 2)
    dt = time.time() - t0
    if not res.success:
        raise RuntimeError(f"trace {sp.name}: motulator simulation failed")
    n = len(rec.u)
    rows = np.array(rec.rows[:n])
    u = np.array(rec.u)
    # Cross-check of the voltage alignment: the duty ratios the controller computed at t_{k-1}
    # (one-period delay) give the voltage applied over [t_k, t_k+1).
    d = np.array(res.ctrl.ref.d_abc)
    u_d = np.concatenate([[0j], sp.u_dc * np.array([complex(abc2complex(x)) for x in d[:n - 1]])])
    return rows, u, dict(sim_s=dt, u_dc_check=float(np.max(np.abs(u - u_d))))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("trace", nargs="?", default="reversal",
                    choices=["startup", "reversal", "small_fast"])
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    sp = spec(a.trace)
    out = a.out or f"{a.trace}_trace.npz"
    rows, u, info = simulate(sp)
    f32 = np.float32
    np.savez_compressed(
        out,
        t_s=rows[:, 1].astype(f32),
        u_ab=np.column_stack([u.real, u.imag]).astype(f32),
        i_ab=rows[:, 3:5].astype(f32),
        load_torque_nm=rows[:, 2].astype(f32),
        omega_mech_rad_s=rows[:, 5].astype(f32),
        theta_e_rad=rows[:, 6].astype(f32),
        versions=np.array(f"motulator {version('motulator')}, scipy {version('scipy')}, "
                          f"numpy {np.__version__}, Python {sys.version.split()[0]}"),
    )
    print(f"{len(rows)} samples -> {out} (sim {info['sim_s']:.1f} s, "
          f"|u_logged - u_from_duties| max {info['u_dc_check']:.2e} V)")


if __name__ == "__main__":
    main()

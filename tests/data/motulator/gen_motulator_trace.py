"""Makes the motulator cross-check fixture for pmsm-sim's plant (see README.md here).

The 2.2 kW motor of docs/design.md, "Reference motors" (surface variant: Rs 3.6 ohm, Ld = Lq = 36 mH,
psi_f 0.545 Wb, 3 pole pairs, J 0.015 kg m^2) with viscous friction B = 0.1 N m s/rad
(chosen large: it damps the open-loop V/f hunting after the load step, so the comparison
stays well conditioned), on a 540 V inverter at 4 kHz, is driven open loop by a V/f voltage
sequence: the frequency ramps
from 0 to 40 Hz electrical (800 rpm) over 0.5 s with a voltage of 20 V + psi_f w_e, then
holds; a 5 N m load step comes at 0.6 s. Each period's voltage is turned into SVPWM duties;
motulator's inverter (zero-order hold, no dead time, no delay) holds them over the period,
so the applied u_alpha_beta is constant over each period, as in pmsm-sim. The script records,
at every sampling instant t_k = k Ts, the applied voltage u[k] (held over [t_k, t_k+1)) and
the machine's currents, speed and angle at t_k.

Usage:  python gen_motulator_trace.py [--out motulator_trace.csv]
Needs:  Python >= 3.12, motulator (0.18.0 was used), numpy.
"""

import argparse
import math
import sys

import numpy as np

from importlib.metadata import version

from motulator.common.model import SolverCfg
from motulator.common.utils import abc2complex
from motulator.drive import model

TS = 250e-6  # sampling (PWM) period, s
DURATION = 1.0  # s
U_DC = 540.0  # V
N_P, R_S, L_S, PSI_F, J, B = 3, 3.6, 36e-3, 0.545, 0.015, 0.1
LOAD_STEP_S, LOAD_NM = 0.6, 5.0


def voltage(t: float, phase: float) -> complex:
    """V/f voltage vector at t for the stator-voltage phase `phase` (rad)."""
    w_e = 2 * math.pi * 40.0 * min(t / 0.5, 1.0)
    return (20.0 + PSI_F * w_e) * complex(math.cos(phase), math.sin(phase))


def svpwm(u: complex) -> np.ndarray:
    """Min-max SVPWM duties for the stator voltage u (V) on the DC bus."""
    v = np.array([u.real, -0.5 * u.real + math.sqrt(3) / 2 * u.imag, -0.5 * u.real - math.sqrt(3) / 2 * u.imag])
    v = v - 0.5 * (v.max() + v.min())
    return np.clip(0.5 + v / U_DC, 0.0, 1.0)


class Prescribed:
    """A 'control system' for motulator's Simulation: it prescribes the duties and records
    the machine at every sampling instant."""

    def __init__(self):
        self.t = 0.0
        self.phase = 0.0
        self.rows = []

    def get_enable(self) -> bool:
        return True

    def __call__(self, mdl):
        k = len(self.rows)
        t = k * TS
        i_ab = complex(mdl.machine.out.i_s_ab)
        w_m = float(mdl.mechanics.out.w_M)
        theta = float(np.real(mdl.machine.state.theta_m))
        d = svpwm(voltage(t, self.phase + math.pi / 2))
        u = U_DC * complex(abc2complex(d))  # what the inverter applies over [t_k, t_k+1)
        load = LOAD_NM if k >= round(LOAD_STEP_S / TS) else 0.0
        mdl.mechanics.set_external_load_torque(load)  # held over [t_k, t_k+1)
        self.rows.append((k, t, u.real, u.imag, load, i_ab.real, i_ab.imag, w_m, theta))
        w_e = 2 * math.pi * 40.0 * min(t / 0.5, 1.0)
        w_next = 2 * math.pi * 40.0 * min((t + TS) / 0.5, 1.0)
        self.phase += 0.5 * (w_e + w_next) * TS
        self.t = t + TS
        return TS, d

    def post_process(self):
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="motulator_trace.csv")
    args = ap.parse_args()

    par = model.SynchronousMachinePars(n_p=N_P, R_s=R_S, L_d=L_S, L_q=L_S, psi_f=PSI_F)
    machine = model.SynchronousMachine(par)
    mechanics = model.MechanicalSystem(J=J, B_L=B)
    converter = model.VoltageSourceConverter(u_dc=U_DC)
    mdl = model.Drive(machine, mechanics, converter, pwm=False, delay=0)
    ctrl = Prescribed()
    sim = model.Simulation(mdl, ctrl, show_progress=False, cfg=SolverCfg(rtol=1e-10, atol=1e-10))
    res = sim.simulate(t_stop=DURATION - TS / 2)
    if not res.success:
        print("motulator simulation failed", file=sys.stderr)
        return 1
    rows = ctrl.rows
    with open(args.out, "w") as f:
        f.write(
            f"# motulator {version('motulator')}, scipy {version('scipy')}, numpy {np.__version__}, "
            f"Python {sys.version.split()[0]}; made by gen_motulator_trace.py\n"
        )
        f.write(
            "k,t_s,u_alpha_v,u_beta_v,load_torque_nm,i_alpha_a,i_beta_a,omega_mech_rad_s,theta_e_rad\n"
        )
        for r in rows:
            f.write(f"{r[0]},{r[1]:.6g}," + ",".join(f"{x:.10g}" for x in r[2:]) + "\n")
    print(f"{len(rows)} samples -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The 5.6 kW PM-SyRM (Baldor ECS101M0H7EF4) of motulator's examples
(plot_6kw_pmsyrm_sat_cvc*.py): algebraic current map i_s(psi_s) of Lelli/Hinkkanen (ICEM 2024),
motulator.drive.utils.SaturationModelPMSyRM. Small-signal and chord constants."""
import numpy as np
from scipy.optimize import root
from motulator.drive import utils

N_P, R_S = 2, 0.63
NOM = utils.NominalValues(U=460, I=8.8, f=60, P=5.6e3, tau=29.7)
BASE = utils.BaseValues.from_nominal(NOM, n_p=N_P)

CURRENT_MAP = utils.SaturationModelPMSyRM(
    a_d0=3.96, a_dd=28.5, S=4, a_q0=5.89, a_qq=2.67, T=6, a_dq=41.5, U=1, V=1,
    a_b=81.75, a_bp=1, k_q=0.1, psi_n=0.804, W=2)


def i_of_psi(psi):
    return complex(CURRENT_MAP(complex(psi)))


def psi_of_i(i, guess=None):
    """Invert the current map by Newton (root)."""
    g = guess if guess is not None else complex(0.48 + 0.02 * i.real, 0.1 * i.imag)
    f = lambda x: [(i_of_psi(x[0] + 1j * x[1]) - i).real, (i_of_psi(x[0] + 1j * x[1]) - i).imag]
    s = root(f, [g.real, g.imag], tol=1e-13)
    assert np.hypot(*s.fun) < 1e-8, s
    return s.x[0] + 1j * s.x[1]


def psi_f():
    from scipy.optimize import brentq
    return brentq(lambda p: i_of_psi(p).real, 0.0, 2.0, xtol=1e-14)


def incremental_L(i, h=1e-4):
    psi0 = psi_of_i(i)
    # Jacobian of i(psi) at psi0, then invert
    Jc = np.zeros((2, 2))
    for k, d in enumerate((h, 1j * h)):
        di = (i_of_psi(psi0 + d) - i_of_psi(psi0 - d)) / (2 * h)
        Jc[:, k] = [di.real, di.imag]
    return np.linalg.inv(Jc)


def torque(i):
    psi = psi_of_i(i)
    return 1.5 * N_P * (i * np.conj(psi)).imag


def mtpa(i_mag):
    """Current angle (from +d axis) maximizing torque at |i| = i_mag; returns i_dq."""
    from scipy.optimize import minimize_scalar
    r = minimize_scalar(lambda a: -torque(i_mag * np.exp(1j * a)), bounds=(np.pi / 2, np.pi * 0.99),
                        method="bounded")
    # PM-SyRM in PMSM convention: PM on d, q is the high-inductance axis -> i_d<0 side (angle > 90 deg)
    return i_mag * np.exp(1j * r.x)


if __name__ == "__main__":
    pf = psi_f()
    L0 = incremental_L(0j)
    print(f"psi_f = {pf:.5f} Wb; L_inc(0) = Ld {L0[0,0]*1e3:.3f} mH, Lq {L0[1,1]*1e3:.3f} mH, Ldq {L0[0,1]*1e3:.4f} mH")
    print(f"base: i {BASE.i:.3f} A peak, w {BASE.w:.2f} rad/s el, w_M {BASE.w_M:.2f}, tau {BASE.tau:.2f} Nm, psi {BASE.psi:.4f}")
    for k in (1.0, 1.5):
        i = mtpa(k * BASE.i)
        psi = psi_of_i(i)
        Li = incremental_L(i)
        print(f"{k} x rated current MTPA: i_dq = {i.real:.3f}{i.imag:+.3f}j A, psi = {psi.real:.4f}{psi.imag:+.4f}j,"
              f" tau = {torque(i):.2f} Nm; chord Ld = {(psi.real-pf)/i.real*1e3:.3f} mH, Lq = {psi.imag/i.imag*1e3:.3f} mH;"
              f" incr Ld {Li[0,0]*1e3:.3f} Lq {Li[1,1]*1e3:.3f} Ldq {Li[0,1]*1e3:.3f} mH")
    # torque needed: what current gives rated torque
    from scipy.optimize import brentq
    for tq in (NOM.tau, 1.5 * NOM.tau):
        m = brentq(lambda a: torque(mtpa(a)) - tq, 1, 60)
        i = mtpa(m)
        print(f"tau {tq:.1f} Nm -> |i| = {m:.2f} A ({m/BASE.i:.2f} pu), i_dq {i.real:.2f}{i.imag:+.2f}j")

"""pyfoc.Ekf told the wrong motor on a reversal under load simulated by a third party:
motulator's 2.2 kW surface PMSM (Rs 3.6 ohm, Ls 36 mH, psi_f 0.545 Wb, 3 pole pairs) under
motulator's sensored current vector control and speed PI, 10 kHz: +12 % of rated speed, the
rated load torque (10 N m) from 0.3 s, the speed reversed to -12 % between 0.6 and 0.8 s (the
drive generates after the zero crossing at 0.74 s), 1.5 s (fixture and its generator in
tests/data/motulator/). Scored from 0.25 s on the samples at |w| >= 5 % of rated speed, no
offset removed. Every told case keeps the lock (no sample more than 45 deg off), the status
is honest, the RMS is as measured (docs/accuracy.md, "A reversal under load on a third-party
plant"), and the defaults are within 1 deg told the flux, Rs or temperature wrong."""
import numpy as np
import pytest

import pyfoc

from conftest import FIRMWARE, ROOT

FIXTURE = ROOT / "tests" / "data" / "motulator" / "reversal_trace.npz"
RATED_W_E = 3 * 1500 * 2 * np.pi / 60


@pytest.fixture(scope="module")
def trace():
    with np.load(FIXTURE) as f:
        return {k: f[k] for k in f.files if k != "versions"}


def score(d, out):
    t = d["t_s"].astype(np.float64)
    w = 3 * d["omega_mech_rad_s"].astype(np.float64)
    scored = (t >= 0.25) & (np.abs(w) >= 0.05 * RATED_W_E)
    e = np.degrees(np.angle(np.exp(1j * (out["theta"] - d["theta_e_rad"]))))[scored]
    tracking = np.asarray(out["status"])[scored] == int(pyfoc.Status.TRACKING)
    lost = np.abs(e) > 45.0
    return float(np.sqrt(np.mean(e**2))), float(lost.mean()), int(np.sum(lost & tracking))


# Told (psi_f, Rs, Ls factors); measured RMS deg of the defaults and of the firmware's filter.
CASES = {
    "the right motor": ((1.0, 1.0, 1.0), 0.014, 0.005),
    "psi_f +10 %": ((1.1, 1.0, 1.0), 0.18, 0.18),
    "psi_f -10 %": ((0.9, 1.0, 1.0), 0.085, 0.086),
    "100 K hot": ((0.88, 1.393, 1.0), 0.094, 10.1),
    "100 K cold": ((1.12, 0.607, 1.0), 0.24, 6.3),
    "Rs +30 %": ((1.0, 1.3, 1.0), 0.089, 6.4),
    "Rs -30 %": ((1.0, 0.7, 1.0), 0.082, 4.9),
    "Ls +20 %": ((1.0, 1.0, 1.2), 2.95, 2.94),
    "Ls -20 %": ((1.0, 1.0, 0.8), 2.95, 2.96),
}


@pytest.mark.parametrize("case", list(CASES))
def test_told_the_wrong_motor_through_a_reversal_under_load(trace, case):
    (fp, fr, fl), defaults, firmware = CASES[case]
    motor = pyfoc.Motor(rs=3.6 * fr, ls=0.036 * fl, psi_f=0.545 * fp, pole_pairs=3)
    u = trace["u_ab"].astype(np.float64)
    i = trace["i_ab"].astype(np.float64)
    for name, kw, measured in (("defaults", {}, defaults), ("firmware", FIRMWARE, firmware)):
        rms, lost, dishonest = score(trace, pyfoc.Ekf(motor, 1e-4, **kw).run(u, i))
        print(f"{case}, {name}: rms {rms:.3f} deg (measured {measured}), {100 * lost:.2f} % "
              f"> 45 deg, {dishonest} samples Tracking while > 45 deg off")
        assert lost == 0.0
        assert dishonest == 0
        assert rms < 1.3 * measured + 0.02
        if name == "defaults" and fl == 1.0:
            # Issue 28's goal through a reversal under load at 10 % speed: 1 deg (a wrong Ls
            # reads as an angle on a surface motor: docs/accuracy.md).
            assert rms <= 1.0

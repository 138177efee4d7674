"""pyfoc.Ekf told the wrong motor on closed-loop runs simulated by a third party: motulator's
models of surface PMSMs under its own sensored current vector control and speed PI, 10 kHz
(fixtures and their generator in tests/data/motulator/):
- `startup`: the 2.2 kW motor (Rs 3.6 ohm, Ls 36 mH, psi_f 0.545 Wb, 3 pole pairs) to 50 % of
  rated speed in 0.3 s, the rated load torque (10 N m) from 0.6 s, 1 s;
- `reversal`: the same motor at +12 % of rated speed, the rated load from 0.3 s, reversed to
  -12 % between 0.6 and 0.8 s (the drive generates after the zero crossing at 0.74 s), 1.5 s;
- `small_fast`: the small fast motor (Rs 0.12 ohm, Ls 0.15 mH, psi_f 6 mWb, 7 pole pairs) to
  50 % of rated speed, its rated load (0.4 N m) from 0.6 s, 1 s.
Scored from 0.25 s on the samples at |w| >= 5 % of rated speed, no offset removed. Every told
case keeps the lock (no sample more than 45 deg off), the status is honest, the RMS is as
measured (docs/accuracy.md, "Closed-loop runs on a third-party plant"), and the defaults meet
issue 28's goals in every flux, resistance and thermal case."""
import numpy as np
import pytest

import pyfoc

from conftest import FIRMWARE, ROOT

DATA = ROOT / "tests" / "data" / "motulator"
# Motor (rs, ls, psi_f, pole pairs) and rated electrical speed of each run.
RUNS = {
    "startup": ((3.6, 0.036, 0.545, 3), 3 * 1500 * 2 * np.pi / 60),
    "reversal": ((3.6, 0.036, 0.545, 3), 3 * 1500 * 2 * np.pi / 60),
    "small_fast": ((0.12, 0.15e-3, 6e-3, 7), 7 * 3429 * 2 * np.pi / 60),
}
TOLD = {  # psi_f, Rs, Ls factors
    "the right motor": (1.0, 1.0, 1.0),
    "psi_f +10 %": (1.1, 1.0, 1.0),
    "psi_f -10 %": (0.9, 1.0, 1.0),
    "100 K hot": (0.88, 1.393, 1.0),
    "100 K cold": (1.12, 0.607, 1.0),
    "Rs +30 %": (1.0, 1.3, 1.0),
    "Rs -30 %": (1.0, 0.7, 1.0),
    "Ls +20 %": (1.0, 1.0, 1.2),
    "Ls -20 %": (1.0, 1.0, 0.8),
}
# Measured RMS deg (defaults, the firmware's filter), in TOLD's order.
MEASURED = {
    "startup": [(0.005, 0.007), (0.018, 0.015), (0.020, 0.020), (0.007, 0.59), (0.26, 0.51),
                (0.11, 0.45), (0.16, 0.40), (2.33, 2.33), (2.34, 2.34)],
    "reversal": [(0.014, 0.005), (0.18, 0.18), (0.085, 0.086), (0.094, 10.1), (0.24, 6.3),
                 (0.088, 6.4), (0.082, 4.9), (2.95, 2.94), (2.95, 2.96)],
    "small_fast": [(0.090, 0.10), (0.078, 0.12), (0.059, 0.088), (0.069, 1.12), (0.11, 0.88),
                   (0.15, 0.81), (0.17, 0.68), (1.18, 1.34), (1.36, 1.34)],
}
# Issue 28's goal for the defaults: 0.5 deg at 50 % speed, 1 deg through a reversal under load
# at 10 % speed; every told case but the inductance's meets it (docs/accuracy.md).
GOAL = {"startup": 0.5, "reversal": 1.0, "small_fast": 0.5}


@pytest.fixture(scope="module")
def traces():
    out = {}
    for run in RUNS:
        with np.load(DATA / f"{run}_trace.npz") as f:
            out[run] = {k: f[k] for k in f.files if k != "versions"}
    return out


def told_run(traces, run, told):
    """The motor told `told` on `run`, the record's `u_ab`, `i_ab` (float64), the trace and the
    mask of the scored samples."""
    d = traces[run]
    (rs, ls, psi, p), w_rated = RUNS[run]
    fp, fr, fl = TOLD[told]
    motor = pyfoc.Motor(rs=rs * fr, ls=ls * fl, psi_f=psi * fp, pole_pairs=p)
    t = d["t_s"].astype(np.float64)
    w = p * d["omega_mech_rad_s"].astype(np.float64)
    scored = (t >= 0.25) & (np.abs(w) >= 0.05 * w_rated)
    return motor, d["u_ab"].astype(np.float64), d["i_ab"].astype(np.float64), d, scored


@pytest.mark.parametrize("told", list(TOLD))
@pytest.mark.parametrize("run", list(RUNS))
def test_told_the_wrong_motor_on_closed_loop_runs(traces, run, told):
    motor, u, i, d, scored = told_run(traces, run, told)
    fl = TOLD[told][2]
    defaults, firmware = MEASURED[run][list(TOLD).index(told)]
    for name, kw, measured in (("defaults", {}, defaults), ("firmware", FIRMWARE, firmware)):
        out = pyfoc.Ekf(motor, 1e-4, **kw).run(u, i)
        e = np.degrees(np.angle(np.exp(1j * (out["theta"] - d["theta_e_rad"]))))[scored]
        tracking = np.asarray(out["status"])[scored] == int(pyfoc.Status.TRACKING)
        lost = np.abs(e) > 45.0
        rms = float(np.sqrt(np.mean(e**2)))
        print(f"{run}, {told}, {name}: rms {rms:.3f} deg (measured {measured}), "
              f"{100 * lost.mean():.2f} % > 45 deg, {int(np.sum(lost & tracking))} samples "
              "Tracking while > 45 deg off")
        assert not lost.any()
        assert not (lost & tracking).any()
        assert rms < 1.3 * measured + 0.02
        if name == "defaults" and fl == 1.0:
            assert rms <= GOAL[run]


def test_a_record_whose_copy_mostly_lost_the_rotor_is_not_retold(traces):
    """The reversal under load told 100 K hot, with current noise of 1.5 % of the record's peak
    current added (seeded): the priming copy reads `Tracking` on 9 % of the rows, and its `Rs`
    (at the lower bound, 1.50 ohm against 3.60) is not told back (a copy must track a quarter
    of the rows: ekf-core's `RETELL_MIN_TRACKING`). Told it, the run lost the rotor (66 deg RMS,
    38 % of the samples more than 45 deg off, some of them `Tracking`); as told, 12.8 deg RMS,
    none more than 45 deg off."""
    motor, u, i, d, scored = told_run(traces, "reversal", "100 K hot")
    i = i + 0.015 * np.abs(i).max() * np.random.default_rng(3).standard_normal(i.shape)
    out = pyfoc.Ekf(motor, 1e-4).run(u, i)
    e = np.degrees(np.angle(np.exp(1j * (out["theta"] - d["theta_e_rad"]))))[scored]
    tracking = np.asarray(out["status"])[scored] == int(pyfoc.Status.TRACKING)
    rms = float(np.sqrt(np.mean(e**2)))
    print(f"noisy reversal told 100 K hot: rms {rms:.2f} deg, Rs told {out['rs'][0]:.3f} ohm")
    assert out["rs"][0] == pytest.approx(RUNS["reversal"][0][0] * TOLD["100 K hot"][1])
    assert not (np.abs(e) > 45.0).any()
    assert not ((np.abs(e) > 45.0) & tracking).any()
    assert rms < 1.3 * 12.8

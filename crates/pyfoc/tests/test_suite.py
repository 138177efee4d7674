"""pyfoc.suite: the observer suite of pmsm-sim from Python."""

import pyfoc


def test_short_suite_report():
    rep = pyfoc.suite(short=True, seed=1)
    assert isinstance(rep["markdown"], str) and "default EKF" in rep["markdown"]
    assert isinstance(rep["all_pass"], bool)
    steady = rep["steady"]
    assert {r["observer"] for r in steady} == {"seed_ekf", "flux_baseline", "default_ekf"}
    motors = {r["motor"] for r in steady}
    surface = {"servo", "industrial2k2", "small_fast"}  # serde names
    assert motors == surface | {"industrial_ipm", "traction_ipm"}, motors
    by = {(r["observer"], r["motor"], r["condition"]): r for r in steady}
    for m in motors:
        for cond in ("50 %", "100 %", "100 %, rated load"):
            ekf, base = by[("default_ekf", m, cond)], by[("flux_baseline", m, cond)]
            # The EKF beats the flux + PLL baseline at and above half speed on every motor.
            assert ekf["angle_rms_deg"] < base["angle_rms_deg"], (m, cond, ekf, base)
            assert ekf["angle_max_deg"] < 5.0, (m, cond, ekf)


def test_suite_is_deterministic_for_a_seed():
    a = pyfoc.suite(short=True, seed=3)
    b = pyfoc.suite(short=True, seed=3)
    assert a["steady"] == b["steady"]

"""pyfoc.simulate: presets, TOML paths and dicts in; aligned arrays and metrics out."""
import threading
import time
import tomllib

import numpy as np
import pytest

import pyfoc

from conftest import ROOT

SCENARIOS = ROOT / "crates" / "pmsm-sim" / "scenarios"


def test_default_scenario_arrays_and_metrics():
    r = pyfoc.simulate("default")
    assert r["completed"] and r["scenario"] == "default"
    n = len(r["t"])
    ts = r["metrics"]["ts_s"]
    assert n == r["metrics"]["periods"] and n > 1000
    np.testing.assert_allclose(np.diff(r["t"]), ts)
    for key, shape in [("theta", (n,)), ("omega", (n,)), ("i_ab", (n, 2)), ("i_ab_meas", (n, 2)),
                       ("u_ab", (n, 2)), ("duties", (n, 3)), ("theta_est", (n,)), ("p_diag", (n, 4)),
                       ("controller_theta_est", (n,))]:
        assert r[key].shape == shape, key
    assert np.all((r["duties"] >= 0) & (r["duties"] <= 1))
    assert np.all(np.isfinite(r["theta_est"]))
    # The arrays agree with the metrics computed in Rust.
    err = np.degrees(np.angle(np.exp(1j * (r["theta_est"] - r["theta"]))))
    np.testing.assert_allclose(err, r["angle_error_deg"], atol=1e-9)
    drive = r["metrics"]["drive"]
    assert drive["fault"] is None
    assert drive["closed_loop_time_s"] < 1.0
    # Sensorless from standstill to rated speed and back to -50 %.
    assert r["speed_rpm"].max() > 1900 and r["speed_rpm"][-1] < -900


def test_ideal_bridge_observer_accuracy_from_arrays():
    r = pyfoc.simulate("servo-ideal")
    late = r["t"] > 0.6
    moving = np.abs(r["omega"]) > 0.05 * r["metrics"]["rated_omega_e_rad_s"]
    err = np.degrees(np.angle(np.exp(1j * (r["theta_est"] - r["theta"]))))[late & moving]
    rms = np.sqrt(np.mean(err**2))
    # Measured: about 0.07 deg rms (desktop f64 EKF, ideal inverter, sensor noise).
    assert rms < 0.3, rms


def test_same_seed_same_result_and_overrides():
    a = pyfoc.simulate("default", duration=0.3, seed=5)
    b = pyfoc.simulate("default", duration=0.3, seed=5)
    c = pyfoc.simulate("default", duration=0.3, seed=6)
    assert len(a["t"]) == round(0.3 / a["metrics"]["ts_s"])
    np.testing.assert_array_equal(a["i_ab_meas"], b["i_ab_meas"])
    np.testing.assert_array_equal(a["theta_est"], b["theta_est"])
    assert not np.array_equal(a["i_ab_meas"], c["i_ab_meas"])


def test_dict_and_path_inputs():
    path = SCENARIOS / "servo-ideal.toml"
    d = tomllib.loads(path.read_text())
    from_dict = pyfoc.simulate(d, duration=0.1)
    from_path = pyfoc.simulate(path, duration=0.1)
    from_str = pyfoc.simulate(str(path), duration=0.1)
    np.testing.assert_array_equal(from_dict["theta_est"], from_path["theta_est"])
    np.testing.assert_array_equal(from_str["u_ab"], from_path["u_ab"])


def test_bad_scenarios_raise_clear_errors():
    with pytest.raises(pyfoc.ConfigError, match="neither a preset"):
        pyfoc.simulate("no-such-preset")
    d = tomllib.loads((SCENARIOS / "servo-ideal.toml").read_text())
    d["motor"]["ld_h"] = -1.0
    with pytest.raises(pyfoc.ConfigError, match="ld_h"):
        pyfoc.simulate(d)
    d = tomllib.loads((SCENARIOS / "servo-ideal.toml").read_text())
    d["motor"]["typo_field"] = 1.0
    with pytest.raises(pyfoc.ConfigError, match="typo_field"):
        pyfoc.simulate(d)
    with pytest.raises(TypeError, match="scenario"):
        pyfoc.simulate(42)
    with pytest.raises(pyfoc.ConfigError, match="duration"):
        pyfoc.simulate("default", duration=-1.0)
    assert issubclass(pyfoc.SimulationError, pyfoc.PyfocError)


def test_simulations_in_threads():
    results = []
    threads = [threading.Thread(target=lambda: results.append(
        pyfoc.simulate("default", duration=0.2)["theta_est"][-1])) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 3 and len(set(results)) == 1


def _log_times(path):
    """(first message's log time, last period's log time, the pmsm_sim metadata) of a log."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        first = next(iter(reader.iter_messages(log_time_order=False)))[2].log_time
        last = [m.log_time for _, _, m in reader.iter_messages(topics=["/pmsm_sim/period"])][-1]
        meta = next(m.metadata for m in reader.iter_metadata() if m.name == "pmsm_sim")
    return first, last, meta


def test_mcap_time_stamps_wall_or_zero(tmp_path):
    """simulate(mcap=...) stamps the log as `pmsm-sim run` does: the wall-clock start plus the
    simulated time by default (recorded as start_time_unix_ns), the simulated time alone with
    log_time="zero"; read_log reads both to the same arrays; another value is refused."""
    before = time.time_ns()
    pyfoc.simulate("default", duration=0.02, mcap=tmp_path / "wall.mcap")
    after = time.time_ns()
    pyfoc.simulate("default", duration=0.02, mcap=tmp_path / "zero.mcap", log_time="zero")
    start, last, meta = _log_times(tmp_path / "wall.mcap")
    assert before <= start <= after and meta["start_time_unix_ns"] == str(start)
    assert last == start + 199 * 100_000
    start, last, meta = _log_times(tmp_path / "zero.mcap")
    assert start == 0 and last == 199 * 100_000 and "start_time_unix_ns" not in meta
    a, b = pyfoc.read_log(tmp_path / "wall.mcap"), pyfoc.read_log(tmp_path / "zero.mcap")
    np.testing.assert_array_equal(a["i_ab"], b["i_ab"])
    np.testing.assert_array_equal(a["t"], b["t"])
    with pytest.raises(pyfoc.ConfigError, match="log_time"):
        pyfoc.simulate("default", duration=0.01, mcap=tmp_path / "x.mcap", log_time="now")

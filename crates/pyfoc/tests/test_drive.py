"""pyfoc.DriveObserver (ekf-core's drive observer) on a simulated log (the default scenario's
MCAP log read back with pyfoc.read_log, as in test_replay.py): finite outputs, chunked runs equal
one run, refused rows REJECTED with the state kept, validation of shapes and periods."""
import threading

import numpy as np
import pytest

import pyfoc

SERVO = dict(rs=2.875, ls=8.5e-3, psi_f=0.175, pole_pairs=4)
TS = 100e-6
FLOATS = ("theta", "omega", "omega_mech", "i_alpha", "i_beta", "nis", "accel", "voltage_lead",
          "rs", "dead_time")


def wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("drive") / "run.mcap"
    pyfoc.simulate("default", duration=0.3, mcap=str(path))
    return pyfoc.read_log(path)


def new():
    return pyfoc.DriveObserver(pyfoc.Motor(**SERVO), TS)


def run(obs, log, a=0, b=None, **kw):
    b = len(log["t"]) if b is None else b
    return obs.run(log["u_ab"][a:b], log["i_ab"][a:b], dt=log["dt"][a:b], **kw)


def test_finite_outputs_and_tracking(log):
    n = len(log["t"])
    obs = new()
    assert obs.ts == TS and "DriveObserver" in repr(obs)
    out = run(obs, log, u_prev=log["u_prev"])
    assert set(out) == set(FLOATS) | {"status"}
    for k in FLOATS:
        assert out[k].dtype == np.float64 and out[k].shape == (n,), k
        assert np.all(np.isfinite(out[k])), k
    assert out["status"].dtype == np.int8
    assert set(np.unique(out["status"])) <= {pyfoc.Status.TRACKING, pyfoc.Status.UNCERTAIN}
    np.testing.assert_allclose(out["omega_mech"], out["omega"] / SERVO["pole_pairs"], rtol=1e-12)
    # On the simulator's clean log it tracks the rotor once it runs (the scoring of replay).
    w = np.abs(log["omega_ref"])
    msk = w >= 0.1 * w.max()
    msk[: int(0.05 / TS)] = False
    err = wrap(out["theta"] - log["theta_ref"])[msk]
    off = np.angle(np.mean(np.exp(1j * err)))
    assert np.degrees(np.sqrt(np.mean(wrap(err - off) ** 2))) < 5.0
    assert np.mean(out["status"][msk] == pyfoc.Status.TRACKING) > 0.5
    assert obs.state.shape == (8,) and obs.covariance.shape == (8, 8)
    assert np.all(np.isfinite(obs.state)) and np.all(np.isfinite(obs.covariance))


def test_without_dt_every_period_is_ts(log):
    a = new().run(log["u_ab"], log["i_ab"], u_prev=log["u_prev"])
    b = run(new(), log, u_prev=log["u_prev"])
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_chunked_runs_equal_one_run(log):
    n = len(log["t"])
    one = new()
    ref = run(one, log, u_prev=log["u_prev"])
    obs = new()
    cuts = [0, 1, 7, 500, 1234, 2000, n]
    parts = [run(obs, log, a, b, u_prev=log["u_prev"] if a == 0 else None)
             for a, b in zip(cuts, cuts[1:])]
    for k in ref:
        np.testing.assert_array_equal(np.concatenate([p[k] for p in parts]), ref[k], err_msg=k)
    np.testing.assert_array_equal(obs.state, one.state)
    np.testing.assert_array_equal(obs.covariance, one.covariance)
    # An empty run changes nothing.
    e = obs.run(np.zeros((0, 2)), np.zeros((0, 2)))
    assert all(v.shape == (0,) for v in e.values())
    np.testing.assert_array_equal(obs.state, one.state)


def test_refused_rows_are_rejected_with_the_state_kept(log):
    m = 1500
    a, b = new(), new()
    ra = run(a, log, 0, m, u_prev=log["u_prev"])
    run(b, log, 0, m, u_prev=log["u_prev"])
    x, p = b.state, b.covariance
    # Copies: writing them changes nothing.
    x[:] = 1.0
    np.testing.assert_array_equal(b.state, a.state)
    # A non-finite current, and a period above 64 ts: refused, the state kept; the outputs
    # repeat the estimate. The voltage of those rows is the last one, so the next run continues
    # as if they had not been there.
    u = np.repeat(log["u_ab"][m - 1][None, :], 3, axis=0)
    i = np.array([[np.nan, 0.0], [0.0, np.inf], log["i_ab"][m]])
    o = b.run(u, i, dt=[TS, TS, 65 * TS])
    np.testing.assert_array_equal(o["status"], [pyfoc.Status.REJECTED] * 3)
    for k in FLOATS:
        assert np.all(np.isfinite(o[k])), k
    np.testing.assert_array_equal(o["theta"], np.full(3, ra["theta"][-1]))
    np.testing.assert_array_equal(b.state, a.state)
    np.testing.assert_array_equal(b.covariance, a.covariance)
    np.testing.assert_array_equal(b.covariance, p)
    ca = run(a, log, m)
    cb = run(b, log, m)
    for k in ca:
        np.testing.assert_array_equal(ca[k], cb[k], err_msg=k)
    # A non-finite voltage refuses the row it predicts (the next one).
    u = log["u_ab"][:5].copy()
    u[2, 1] = np.nan
    o = new().run(u, log["i_ab"][:5])
    np.testing.assert_array_equal(o["status"] == pyfoc.Status.REJECTED, [0, 0, 0, 1, 0])


def test_shapes_and_periods_are_validated(log):
    obs = new()
    u, i = log["u_ab"][:10], log["i_ab"][:10]
    for bad, name in (
        (dict(u_ab=u[:, :1], i_ab=i), "u_ab"),
        (dict(u_ab=u.ravel(), i_ab=i), "u_ab"),
        (dict(u_ab=u, i_ab=i[:, :1]), "i_ab"),
        (dict(u_ab=u, i_ab=i[None]), "i_ab"),
        (dict(u_ab=u, i_ab=i, u_prev=[1.0, 2.0, 3.0]), "u_prev"),
        (dict(u_ab=u, i_ab=i, dt=np.full(9, TS)), "dt"),
        (dict(u_ab=u, i_ab=i, dt=np.full((10, 1), TS)), "dt"),
    ):
        with pytest.raises(ValueError, match=name):
            obs.run(bad.pop("u_ab"), bad.pop("i_ab"), **bad)
    with pytest.raises(ValueError, match="same length"):
        obs.run(u, i[:9])
    for bad in ([TS] * 9 + [np.nan], [TS] * 9 + [0.0], [TS] * 9 + [-TS], [TS] * 9 + [np.inf]):
        with pytest.raises(ValueError, match="dt"):
            obs.run(u, i, dt=bad)
    with pytest.raises(TypeError, match="dt"):
        obs.run(u, i, dt="x")
    with pytest.raises(TypeError, match="u_ab"):
        obs.run(None, i)
    # Nothing moved.
    np.testing.assert_array_equal(obs.state, new().state)
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.DriveObserver(pyfoc.Motor(**SERVO), -1.0)
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.DriveObserver(pyfoc.Motor(**SERVO), float("nan"))


def test_threads_serialize_on_one_observer(log):
    """Two threads on one observer: each call runs whole (the lock), the GIL is released."""
    obs = new()
    res = []

    def go():
        res.append(run(obs, log, 0, 1000)["theta"])

    ts = [threading.Thread(target=go) for _ in range(2)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert len(res) == 2 and all(np.all(np.isfinite(r)) for r in res)
    one = new()
    run(one, log, 0, 1000)
    first = run(one, log, 0, 1000)["theta"]
    # The second call continued from the first's state.
    assert any(np.array_equal(r, first) for r in res)


def test_calibration_is_the_speed_weighted_mean_of_tracked_rows(log):
    obs = new()
    assert obs.calibration() is None
    out = run(obs, log, u_prev=log["u_prev"])
    c = obs.calibration()
    assert set(c) == {"voltage_delay_s", "rs_ohm", "inverter_voltage_v", "samples"}
    trk = out["status"] == pyfoc.Status.TRACKING
    w2 = np.where(trk, out["omega"] ** 2, 0.0)
    assert c["samples"] == int(np.sum(trk & (w2 > 0)))
    np.testing.assert_allclose(c["voltage_delay_s"], -np.sum(w2 * out["voltage_lead"]) / w2.sum(),
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(c["rs_ohm"], np.sum(w2 * out["rs"]) / w2.sum(), rtol=1e-9)
    np.testing.assert_allclose(c["inverter_voltage_v"], np.sum(w2 * out["dead_time"]) / w2.sum(),
                               rtol=1e-9, atol=1e-12)
    # The second pass takes it as it is.
    ekf = pyfoc.Ekf(pyfoc.Motor(c["rs_ohm"], SERVO["ls"], SERVO["psi_f"], SERVO["pole_pairs"]), TS,
                    voltage_delay_s=c["voltage_delay_s"],
                    inverter_voltage_v=c["inverter_voltage_v"], acceleration_feedforward=True)
    e = ekf.run(log["u_ab"], log["i_ab"], u_prev=log["u_prev"], dt=log["dt"])
    assert np.all(np.isfinite(e["theta"]))

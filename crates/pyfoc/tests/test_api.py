"""The Python API: shapes, dtypes, errors, chunking, non-finite samples, threads."""
import enum
import math
import threading

import numpy as np
import pytest

import pyfoc


def run_threads(*targets):
    """Runs each callable on a thread of its own, all at once, and waits for every one."""
    threads = [threading.Thread(target=t) for t in targets]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


SERVO = dict(rs=2.875, ls=8.5e-3, psi_f=0.175, pole_pairs=4)


def record(n=3000, ts=1e-4, w=800.0, seed=0):
    """A rotor at constant speed with ideal dq feed-forward (exact enough to exercise the API)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    th = 0.4 + w * ts * k
    iq = 2.0
    i_ab = np.column_stack([-iq * np.sin(th), iq * np.cos(th)]) + 0.01 * rng.standard_normal((n, 2))
    uq = SERVO["rs"] * iq + w * SERVO["psi_f"]
    ud = -w * SERVO["ls"] * iq
    thm = th + 0.5 * w * ts
    u_ab = np.column_stack([ud * np.cos(thm) - uq * np.sin(thm), ud * np.sin(thm) + uq * np.cos(thm)])
    return u_ab, i_ab, np.angle(np.exp(1j * th))


def test_motor_and_ekf_construction_errors():
    m = pyfoc.Motor(**SERVO)
    assert m.pole_pairs == 4 and m.ld == m.lq == SERVO["ls"]
    for kwargs in [dict(SERVO, rs=-1.0), dict(SERVO, ls=0.0), dict(SERVO, psi_f=float("nan")),
                   dict(SERVO, pole_pairs=0), dict(SERVO, pole_pairs=-3)]:
        with pytest.raises(pyfoc.ConfigError):
            pyfoc.Motor(**kwargs)
    assert issubclass(pyfoc.ConfigError, pyfoc.PyfocError)
    assert issubclass(pyfoc.PyfocError, ValueError)
    with pytest.raises(pyfoc.ConfigError, match="ts_s"):
        pyfoc.Ekf(m, ts=0.0)
    with pytest.raises(pyfoc.ConfigError, match="discretization"):
        pyfoc.Ekf(m, ts=1e-4, discretization="rk4")
    with pytest.raises(pyfoc.ConfigError, match="dtype"):
        pyfoc.Ekf(m, ts=1e-4, dtype="float16")
    with pytest.raises(pyfoc.ConfigError, match="Q"):
        pyfoc.Ekf(m, ts=1e-4, q=[1.0, 1.0, -1.0, 1.0])
    with pytest.raises(pyfoc.ConfigError, match="R"):
        pyfoc.Ekf(m, ts=1e-4, r=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="q"):
        pyfoc.Ekf(m, ts=1e-4, q=np.eye(3))
    with pytest.raises(ValueError, match="x0"):
        pyfoc.Ekf(m, ts=1e-4, x0=[1.0, 2.0])
    # Absurd saliency is refused; an inversely salient motor is accepted and reported.
    with pytest.raises(pyfoc.ConfigError, match="lq_h / ld_h"):
        pyfoc.Motor(**SERVO, ld=1e-3, lq=20e-3)
    with pytest.raises(pyfoc.ConfigError, match="ld and lq"):
        pyfoc.Motor(2.875, None, 0.175, 4, ld=8e-3)
    assert pyfoc.Motor(**SERVO, ld=9e-3, lq=8e-3).kind == "inverse_salient"
    ipm = pyfoc.Motor(3.6, None, 0.5, 3, ld=30e-3, lq=42e-3)
    assert ipm.kind == "interior" and ipm.ls == pytest.approx(36e-3)
    assert pyfoc.Motor(**SERVO).kind == "surface"


def test_run_shapes_and_dtypes_are_checked():
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    good = np.zeros((10, 2))
    with pytest.raises(ValueError, match="u_ab"):
        ekf.run(np.zeros((10, 3)), good)
    with pytest.raises(ValueError, match="i_ab"):
        ekf.run(good, np.zeros(20))
    with pytest.raises(ValueError, match="same length"):
        ekf.run(good, np.zeros((9, 2)))
    with pytest.raises(TypeError, match="u_ab"):
        ekf.run(np.full((10, 2), "x"), good)
    with pytest.raises(TypeError, match="i_ab"):
        ekf.run(good, np.zeros((10, 2), dtype=complex))
    with pytest.raises(ValueError, match="u_prev"):
        ekf.step([1.0, 2.0, 3.0], [0.0, 0.0])
    # Nothing above touched the filter.
    assert np.all(ekf.state == 0.0)
    # float32, int, non-contiguous and read-only inputs are accepted.
    u, i, _ = record(200)
    ro = i.copy()
    ro.setflags(write=False)
    a = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(u.astype(np.float32), ro)
    b = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(
        np.asfortranarray(u.astype(np.float32)), np.asfortranarray(i))
    np.testing.assert_array_equal(a["theta"], b["theta"])
    assert pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(np.zeros((0, 2)), np.zeros((0, 2)))["theta"].shape == (0,)


def test_run_tracks_and_output_layout():
    u, i, th = record()
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    out = ekf.run(u, i)
    assert set(out) == {"theta", "omega", "omega_mech", "i_alpha", "i_beta", "nis", "psi_f", "rs",
                        "winding_temperature", "status"}
    assert all(v.shape == (len(u),) for v in out.values())
    assert out["status"].dtype == np.int8
    err = np.degrees(np.angle(np.exp(1j * (out["theta"] - th))))
    assert np.sqrt(np.mean(err[1000:] ** 2)) < 1.0
    np.testing.assert_allclose(out["omega"][-1], 800.0, rtol=1e-2)
    np.testing.assert_allclose(out["omega_mech"], out["omega"] / 4)
    assert out["status"][-1] == pyfoc.Status.TRACKING
    assert ekf.state.shape == (4,) and ekf.covariance.shape == (4, 4)
    np.testing.assert_allclose(ekf.covariance, ekf.covariance.T)
    assert ekf.state[3] == out["theta"][-1]


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_chunked_run_equals_one_run(dtype):
    """Chunks continue where the last one stopped; the record primes the calibration once
    (`prime` before the chunks, as the first `run` of one whole record does itself)."""
    u, i, _ = record(2000)
    one = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype).run(u, i)
    chunked = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype)
    chunked.prime(u, i)
    parts = [chunked.run(u[a:b], i[a:b]) for a, b in [(0, 1), (1, 700), (700, 701), (701, 2000)]]
    for key in one:
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), one[key])


def test_prime_refuses_bad_records_and_skips_bad_rows():
    """`Ekf.prime` checks its arrays as `run` does (wrong shapes, lengths, periods raise before
    anything moves); rows the filter refuses (NaN) are skipped by the copy, as `run` skips them."""
    u, i, _, u0 = led_record(4000)
    motor, ts = pyfoc.Motor(**SERVO), 1e-4
    ekf = pyfoc.Ekf(motor, ts)
    before = (ekf.state.copy(), ekf.covariance.copy())
    with pytest.raises(ValueError, match="same length"):
        ekf.prime(u[:10], i[:9])
    with pytest.raises(ValueError, match="u_ab"):
        ekf.prime(u[:, :1], i)
    with pytest.raises(ValueError, match="dt"):
        ekf.prime(u, i, dt=np.full(len(u), -1.0))
    with pytest.raises(ValueError, match="u_prev"):
        ekf.prime(u, i, u_prev=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(ekf.state, before[0])
    np.testing.assert_array_equal(ekf.covariance, before[1])
    # Refused prime calls leave the filter fresh: its first run still primes.
    np.testing.assert_array_equal(ekf.run(u, i, u_prev=u0)["theta"],
                                  pyfoc.Ekf(motor, ts).run(u, i, u_prev=u0)["theta"])
    bad = i.copy()
    bad[100:110] = np.nan
    delay = pyfoc.Ekf(motor, ts).prime(u, bad, u_prev=u0)
    assert delay is None or math.isfinite(delay)


def led_record(n=10000, lead=0.8, ts=1e-4, iq=2.0, noise=0.01, seed=0):
    """A servo motor under a deadbeat current drive (i_q = 2 A, i_d = 0 at every sample) whose
    speed swings between 1200 and 2800 rad/s el. at 2 Hz. Each period's voltage is held in the
    stationary frame (the exact response over the period at its mean speed), and the logged
    voltage lags the applied one by `lead` periods: the applied vector turned back by
    w lead Ts, as a firmware that rotates its command for the time until the PWM takes it.
    Returns `u_ab` (row k predicts row k + 1), `i_ab`, the true angle and `u_prev`."""
    rs, ls, psi = SERVO["rs"], SERVO["ls"], SERVO["psi_f"]
    a = rs / ls
    alpha = np.exp(-a * ts)
    t = np.arange(n + 1) * ts
    th = 0.4 + 2000.0 * t - 800.0 / (4.0 * np.pi) * (np.cos(4.0 * np.pi * t) - 1.0)
    cur = iq * 1j * np.exp(1j * th)
    w = np.diff(th) / ts
    emf = -1j * w * psi / ls * np.exp(1j * th[:-1]) * (np.exp(1j * w * ts) - alpha) / (a + 1j * w)
    applied = (cur[1:] - alpha * cur[:-1] - emf) * rs / (1.0 - alpha)
    logged = applied * np.exp(-1j * w * lead * ts)
    rng = np.random.default_rng(seed)
    meas = cur[1:] + noise * (rng.standard_normal(n) + 1j * rng.standard_normal(n))

    def col(z):
        return np.column_stack([z.real, z.imag])

    u_ab = col(np.concatenate([logged[1:], logged[-1:]]))
    return u_ab, col(meas), th[1:], col(logged[:1])[0]


def offset_free_rms(theta, th, skip=1000):
    e = np.angle(np.exp(1j * (theta[skip:] - th[skip:])))
    e = np.angle(np.exp(1j * (e - np.angle(np.mean(np.exp(1j * e))))))
    return float(np.degrees(np.sqrt(np.mean(e**2))))


def test_first_run_primes_the_input_calibration_with_its_record():
    """The applied voltage leads the logged one by 0.8 periods. The online calibration finds
    the lead from the speed swings only after a while, and a filter that switches lead part-way
    leaves two offsets; the first `run` of a new filter therefore primes it with its record (the
    delay a copy's calibration handed over last). Measured RMS deg, offset removed: primed
    0.17, not primed 3.02, the firmware's filter 2.31; the delay found -0.776 Ts. With no lead
    nothing is handed over, and the defaults are the filter without the calibration bit for
    bit."""
    motor, ts = pyfoc.Motor(**SERVO), 1e-4
    u, i, th, u0 = led_record()
    primer = pyfoc.Ekf(motor, ts)
    delay = primer.prime(u, i, u_prev=u0)
    assert delay is not None and abs(delay / ts + 0.8) < 0.08
    primed = pyfoc.Ekf(motor, ts).run(u, i, u_prev=u0)
    # Not primed: `prime` on one row hands nothing over and ends the filter's fresh state.
    plain = pyfoc.Ekf(motor, ts)
    assert plain.prime(u[:1], i[:1], u_prev=u0) is None
    unprimed = plain.run(u, i, u_prev=u0)
    firmware = pyfoc.Ekf(motor, ts, acceleration_feedforward=False,
                         input_calibration=False).run(u, i, u_prev=u0)
    rms = [offset_free_rms(o["theta"], th) for o in (primed, unprimed, firmware)]
    print("primed / not primed / firmware RMS deg:", rms)
    assert rms[0] < 0.25 and rms[0] < 0.1 * rms[1] and rms[0] < 0.1 * rms[2]
    # A step before the first run also ends the fresh state: that run is not primed.
    stepped, reference = pyfoc.Ekf(motor, ts), pyfoc.Ekf(motor, ts)
    reference.prime(u[:1], i[:1], u_prev=u0)
    for f in (stepped, reference):
        f.step(u0, i[0])
    np.testing.assert_array_equal(stepped.run(u[1:], i[1:], u_prev=u[0])["theta"],
                                  reference.run(u[1:], i[1:], u_prev=u[0])["theta"])
    # Without the calibration, or without a lead, nothing is primed.
    off = pyfoc.Ekf(motor, ts, input_calibration=False)
    assert off.prime(u, i, u_prev=u0) is None
    u, i, th, u0 = led_record(lead=0.0)
    assert pyfoc.Ekf(motor, ts).prime(u, i, u_prev=u0) is None
    np.testing.assert_array_equal(
        pyfoc.Ekf(motor, ts).run(u, i, u_prev=u0)["theta"],
        pyfoc.Ekf(motor, ts, input_calibration=False).run(u, i, u_prev=u0)["theta"])


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_run_into_out_equals_run_and_reuses_the_arrays(dtype):
    u, i, _ = record(2000)
    one = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype).run(u, i)
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype)
    ekf.prime(u, i)  # the whole record primes the calibration, as one run's own rows do
    buf = ekf.run(u[:500], i[:500])
    ids = {k: id(v) for k, v in buf.items()}
    for a in range(500, 2000, 500):
        got = ekf.run(u[a:a + 500], i[a:a + 500], out=buf)
        assert got is buf and {k: id(v) for k, v in got.items()} == ids
        for key in one:
            np.testing.assert_array_equal(got[key], one[key][a:a + 500])


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_long_run_equals_short_runs(dtype):
    # A long run maps its output pages on a second thread and filters block by block
    # (2^14 rows); short runs do neither. The rows must not depend on it.
    n = 70_001
    u, i, _ = record(n)
    one = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype).run(u, i)
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype)
    ekf.prime(u, i)  # the whole record primes the calibration, as one run's own rows do
    parts = [ekf.run(u[a:a + 7000], i[a:a + 7000]) for a in range(0, n, 7000)]
    for key in one:
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), one[key])


def test_long_run_reads_any_layout_and_writes_out_like_fresh():
    # A long run (2^16 rows and more), into fresh outputs or an out= dict, copies its inputs
    # block by block on a helper thread while the filter starts; every input layout, a given
    # u_prev, an out= dict and a filter whose lock another call holds (both in sequence) give
    # the same rows.
    n = 70_001
    u, i, _ = record(n)
    make = lambda: pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)  # noqa: E731
    ref = make().run(u, i, u_prev=[1.0, -2.0])
    wide_u, wide_i = np.repeat(u, 2, axis=0), np.repeat(i, 2, axis=0)
    layouts = [
        (np.asfortranarray(u), np.asfortranarray(i)),
        (wide_u[::2], wide_i[::2]),  # strided views
        (u[::-1][::-1], i.copy()),
        (u.tolist(), np.ascontiguousarray(i.T).T),  # nested lists; a transposed view
    ]
    for uu, ii in layouts:
        got = make().run(uu, ii, u_prev=[1.0, -2.0])
        for key in ref:
            np.testing.assert_array_equal(got[key], ref[key])
    out = {k: np.full_like(v, -1) for k, v in ref.items()}
    ekf = make()
    assert ekf.run(u, i, u_prev=[1.0, -2.0], out=out) is out
    for key in ref:
        np.testing.assert_array_equal(out[key], ref[key])
    np.testing.assert_array_equal(ekf.u_last, u[-1])
    # Fresh float outputs are row views of one array; writing one leaves the others.
    assert ref["theta"].base is not None and ref["theta"].base is ref["omega"].base
    before = ref["omega"].copy()
    ref["theta"][:] = 0.0
    np.testing.assert_array_equal(ref["omega"], before)
    # Two long runs on one filter at once: serialized, equal to two in sequence.
    shared, seq = make(), make()
    run_threads(*[lambda: shared.run(u, i)] * 2)
    seq.run(u, i)
    seq.run(u, i)
    np.testing.assert_array_equal(shared.state, seq.state)


def test_bad_out_raises_and_leaves_filter_and_arrays_alone():
    u, i, _ = record(100)
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    good = ekf.run(u, i)
    state, cov, u_last = ekf.state.copy(), ekf.covariance.copy(), ekf.u_last.copy()

    def variant(key, value):
        d = {k: v.copy() for k, v in good.items()}
        if value is None:
            del d[key]
        else:
            d[key] = value
        return d

    ro = good["nis"].copy()
    ro.setflags(write=False)
    shared = good["omega"].copy()
    cases = [
        (variant("rs", None), 'no array "rs"'),
        (variant("theta", np.zeros(100, dtype=np.float32)), "float64"),
        (variant("status", np.zeros(100)), "int8"),
        (variant("omega", np.zeros(99)), "length 100"),
        (variant("omega", np.zeros((100, 1))), "one-dimensional"),
        (variant("psi_f", np.zeros(200)[::2]), "C-contiguous"),
        (variant("nis", ro), "cannot be written"),
        ({**variant("theta", shared), "omega": shared}, "cannot be written"),
    ]
    for out, msg in cases:
        before = {k: v.copy() for k, v in out.items()}
        with pytest.raises(ValueError, match=msg):
            ekf.run(u, i, out=out)
        for k, v in out.items():
            np.testing.assert_array_equal(v, before[k])
    overlap = np.zeros(200)
    with pytest.raises(ValueError, match="cannot be written"):
        ekf.run(u, i, out={**variant("theta", overlap[:100]), "omega": overlap[50:150]})
    with pytest.raises(TypeError):
        ekf.run(u, i, out=[good[k] for k in good])
    np.testing.assert_array_equal(ekf.state, state)
    np.testing.assert_array_equal(ekf.covariance, cov)
    np.testing.assert_array_equal(ekf.u_last, u_last)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_step_equals_run(dtype):
    # 300 rows: the float32 filter's run writes whole blocks of 64 rows through a buffer and
    # the last 44 one by one; rejected rows inside a block (NaN current, infinite voltage).
    u, i, _ = record(300)
    i[150] = [np.nan, 0.0]
    u[200] = [np.inf, 0.0]
    out = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype).run(u, i)
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype)
    u_prev = np.zeros(2)
    for k in range(len(u)):
        est = ekf.step(u_prev, i[k])
        for key in out:
            if key != "status":
                np.testing.assert_array_equal(est[key], out[key][k], err_msg=f"{key}[{k}]")
        assert isinstance(est["status"], pyfoc.Status) and est["status"] == out["status"][k]
        u_prev = u[k]
    assert np.flatnonzero(out["status"] == pyfoc.Status.REJECTED).tolist() == [150, 201]


def test_status_is_one_int_enum_for_run_and_step():
    assert issubclass(pyfoc.Status, enum.IntEnum)
    assert [(m.name, m.value) for m in pyfoc.Status] == [("TRACKING", 0), ("UNCERTAIN", 1), ("REJECTED", 2)]
    u, i, _ = record(300)
    i[150] = np.nan
    out = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(u, i)
    # The int8 codes are the enum's values: each converts back to a member.
    assert {pyfoc.Status(int(v)) for v in out["status"]} == {
        pyfoc.Status.UNCERTAIN, pyfoc.Status.TRACKING, pyfoc.Status.REJECTED}
    assert out["status"][150] == pyfoc.Status.REJECTED
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    assert ekf.step([0.0, 0.0], [0.0, 0.0])["status"] is pyfoc.Status.UNCERTAIN


@pytest.mark.parametrize("attr", ["state", "covariance", "u_last", "ts", "dtype"])
def test_ekf_properties_are_read_only(attr):
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    with pytest.raises(AttributeError):
        setattr(ekf, attr, getattr(ekf, attr))
    # The arrays are copies: writing into one does not reach the filter.
    value = getattr(ekf, attr)
    if isinstance(value, np.ndarray):
        value[...] = 7.0
        assert np.all(getattr(ekf, attr) != 7.0)


@pytest.mark.parametrize("attr", ["rs", "ls", "psi_f", "pole_pairs", "ld", "lq"])
def test_motor_is_immutable(attr):
    m = pyfoc.Motor(**SERVO)
    with pytest.raises(AttributeError):
        setattr(m, attr, 1.0)
    assert getattr(m, attr) == SERVO.get(attr, SERVO["ls"])


def test_float32_filter_is_close_to_float64():
    u, i, _ = record(3000)
    a = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(u, i)
    b = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype="float32").run(u, i)
    d = np.angle(np.exp(1j * (a["theta"] - b["theta"])))
    assert np.max(np.abs(d[500:])) < 1e-3


def test_non_finite_samples_are_rejected_and_reported():
    u, i, _ = record(500)
    bad_i = i.copy()
    bad_i[100] = [np.nan, 0.0]
    bad_u = u.copy()
    bad_u[200] = [np.inf, 0.0]  # row 201 predicts with it
    ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    out = ekf.run(bad_u, bad_i)
    assert np.flatnonzero(out["status"] == pyfoc.Status.REJECTED).tolist() == [100, 201]
    # A rejected row repeats the previous estimate: the state was kept.
    assert out["theta"][100] == out["theta"][99]
    assert out["theta"][201] == out["theta"][200]
    assert np.all(np.isfinite(out["theta"])) and np.all(np.isfinite(ekf.covariance))
    est = ekf.step([np.nan, 0.0], [0.0, 0.0])
    assert est["status"] is pyfoc.Status.REJECTED
    before = ekf.state.copy()
    with pytest.raises(pyfoc.FilterError):
        ekf.reset([0.0, 0.0, np.nan, 0.0], np.eye(4))
    np.testing.assert_array_equal(ekf.state, before)


def test_threads_each_get_a_result():
    u, i, _ = record(20000)
    results, errors = [], []

    def work():
        try:
            results.append(pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4).run(u, i)["theta"][-1])
        except Exception as e:  # noqa: BLE001 - collected and asserted below
            errors.append(e)

    run_threads(*[work] * 4)
    assert not errors and len(results) == 4 and len(set(results)) == 1
    # One filter shared by threads: each call gets a result or a Python exception, no crash.
    shared = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4)
    outcomes = []

    def share():
        try:
            shared.run(u, i)
            outcomes.append("ok")
        except RuntimeError as e:
            outcomes.append(type(e).__name__)

    run_threads(*[share] * 4)
    assert len(outcomes) == 4 and "ok" in outcomes


def test_tracking_outputs_follow_a_mismatched_flux():
    """Told a flux 10 % high, the default Ekf tracks the true one; tracking="off" keeps the told
    one and its angle is biased by several degrees."""
    u, i, th = record(8000)
    told = dict(SERVO, psi_f=SERVO["psi_f"] * 1.1)
    out = pyfoc.Ekf(pyfoc.Motor(**told), ts=1e-4).run(u, i)
    np.testing.assert_allclose(out["psi_f"][-1], SERVO["psi_f"], rtol=0.01)
    assert np.all(out["rs"] > 0) and np.all(np.isfinite(out["winding_temperature"]))
    err = np.degrees(np.angle(np.exp(1j * (out["theta"] - th))))
    off = pyfoc.Ekf(pyfoc.Motor(**told), ts=1e-4, tracking="off").run(u, i)
    err_off = np.degrees(np.angle(np.exp(1j * (off["theta"] - th))))
    assert np.all(off["psi_f"] == told["psi_f"])
    rms = np.sqrt(np.mean(err[6000:] ** 2))
    rms_off = np.sqrt(np.mean(err_off[6000:] ** 2))
    assert rms < 0.5 and rms_off > 3.0, (rms, rms_off)
    step = pyfoc.Ekf(pyfoc.Motor(**told), ts=1e-4, tracking="flux").step(u[0], i[0])
    assert step["psi_f"] == told["psi_f"] and step["rs"] == SERVO["rs"]
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, tracking="rs")


IPM = dict(rs=3.6, psi_f=0.5, pole_pairs=3, ld=30e-3, lq=42e-3)


def test_interior_motor_uses_ld_and_lq():
    """An interior motor (Lq/Ld 1.4) in steady state with an MTPA-like negative i_d: the Ekf
    told Ld and Lq tracks it to a fraction of a degree, a surface model with the mean
    inductance is degrees off."""
    n, ts, w = 6000, 1e-4, 700.0
    rng = np.random.default_rng(3)
    th = 0.2 + w * ts * np.arange(n)
    i_d, i_q = -1.5, 6.0
    c, s = np.cos(th), np.sin(th)
    i_ab = np.column_stack([i_d * c - i_q * s, i_d * s + i_q * c]) + 0.01 * rng.standard_normal((n, 2))
    ud = IPM["rs"] * i_d - w * IPM["lq"] * i_q
    uq = IPM["rs"] * i_q + w * (IPM["ld"] * i_d + IPM["psi_f"])
    thm = th + 0.5 * w * ts
    u_ab = np.column_stack([ud * np.cos(thm) - uq * np.sin(thm), ud * np.sin(thm) + uq * np.cos(thm)])
    truth = np.angle(np.exp(1j * th))

    def rms(motor):
        out = pyfoc.Ekf(motor, ts=ts, tracking="off").run(u_ab, i_ab)
        err = np.degrees(np.angle(np.exp(1j * (out["theta"] - truth))))
        return float(np.sqrt(np.mean(err[3000:] ** 2)))

    salient = pyfoc.Motor(IPM["rs"], None, IPM["psi_f"], IPM["pole_pairs"], ld=IPM["ld"], lq=IPM["lq"])
    surface = pyfoc.Motor(IPM["rs"], salient.ls, IPM["psi_f"], IPM["pole_pairs"])
    assert salient.kind == "interior" and surface.kind == "surface"
    rms_salient, rms_surface = rms(salient), rms(surface)
    assert rms_salient < 0.3 and rms_surface > 2.0, (rms_salient, rms_surface)


def test_motor_from_datasheet_converts_line_to_line_and_kt_kv():
    m = pyfoc.Motor.from_datasheet(pole_pairs=4, r_ll=5.75, l_ll=17e-3, kt_nm_per_a=1.05)
    assert m.rs == pytest.approx(2.875, rel=1e-12)
    assert m.ld == m.lq == pytest.approx(8.5e-3, rel=1e-12)
    assert m.psi_f == pytest.approx(0.175, rel=1e-12)
    # Kv: rpm per volt of line-to-line peak EMF; sqrt(3) p psi_f volts per mechanical rad/s.
    kv = 60.0 / (2 * math.pi * math.sqrt(3) * 4 * 0.175)
    m2 = pyfoc.Motor.from_datasheet(pole_pairs=4, r_ll=5.75, l_ll=17e-3, kv_rpm_per_v=kv)
    assert m2.psi_f == pytest.approx(0.175, rel=1e-12)
    ipm = pyfoc.Motor.from_datasheet(
        pole_pairs=3, r_ll=7.2, ld_ll=60e-3, lq_ll=84e-3, kt_nm_per_a=2.25
    )
    assert (ipm.ld, ipm.lq, ipm.kind) == (pytest.approx(30e-3), pytest.approx(42e-3), "interior")


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(kt_nm_per_a=1.0, kv_rpm_per_v=100.0), "exactly one"),
        (dict(), "exactly one"),
        (dict(kt_nm_per_a=-1.0), "kt_nm_per_a"),
        (dict(kt_nm_per_a=1.0, l_ll=None), "l_ll"),
        (dict(kt_nm_per_a=1.0, r_ll=float("nan")), "r_ll"),
        (dict(kt_nm_per_a=1.0, pole_pairs=0), "pole_pairs"),
    ],
)
def test_motor_from_datasheet_refuses_bad_values_naming_them(kwargs, words):
    args = dict(pole_pairs=4, r_ll=5.75, l_ll=17e-3)
    args.update(kwargs)
    with pytest.raises(pyfoc.ConfigError, match=words):
        pyfoc.Motor.from_datasheet(**args)


@pytest.mark.parametrize(
    "args, words",
    [
        ((1e300, 8.5e-3, 0.175, 4), "rs_ohm"),
        ((2.875, 8.5e-3, 0.175, 2**31), "pole_pairs"),
        ((2.875, 8.5e-3, 1e9, 4), "psi_f_wb"),
    ],
)
def test_motor_refuses_absurd_values_with_their_range(args, words):
    with pytest.raises(pyfoc.ConfigError, match=words + ".*range"):
        pyfoc.Motor(*args)

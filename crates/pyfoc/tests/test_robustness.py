"""pyfoc never crashes the interpreter: every malformed input gets a result or a Python exception.

Covers wrong shapes and dtypes, non-contiguous, read-only and broadcast arrays, NaN/inf,
empty and absurdly large arrays, bad motor and filter parameters, calls from several threads
(also on one shared Ekf), and simulate() with malformed dicts and paths. Each call runs in
this process: an abort would take pytest down with it, which is what these tests rule out.
"""
import math
import os
import threading

import numpy as np
import pytest

import pyfoc
from test_api import run_threads

SERVO = dict(rs=2.875, ls=8.5e-3, psi_f=0.175, pole_pairs=4)
TS = 1e-4


def motor():
    return pyfoc.Motor(**SERVO)


def ekf(**kw):
    return pyfoc.Ekf(motor(), TS, **kw)


def good(n=50):
    rng = np.random.default_rng(1)
    return rng.standard_normal((n, 2)), rng.standard_normal((n, 2))


def huge_view(rows):
    """A read-only broadcast view of `rows` x 2 zeros: no memory behind it."""
    return np.broadcast_to(np.zeros(2), (rows, 2))


# --- shapes -----------------------------------------------------------------------------------

BAD_SHAPES = [
    np.zeros(10),
    np.zeros((10, 3)),
    np.zeros((10, 1)),
    np.zeros((10, 2, 1)),
    np.zeros((2, 10)),
    np.zeros((0,)),
    np.zeros((0, 3)),
    np.zeros((5, 0)),
    np.float64(1.0),
    3.0,
    [],
    [[1.0, 2.0], [3.0]],  # ragged
]


@pytest.mark.parametrize("bad", BAD_SHAPES, ids=lambda b: repr(np.shape(b)) if not isinstance(b, list) else "list")
@pytest.mark.parametrize("which", ["u_ab", "i_ab"])
def test_run_bad_shapes_raise(bad, which):
    f = ekf()
    u, i = good(10)
    args = {"u_ab": u, "i_ab": i}
    args[which] = bad
    with pytest.raises((ValueError, TypeError)):
        f.run(**args)
    # The filter was not touched.
    assert np.all(f.state == 0.0)


@pytest.mark.parametrize("bad", [[1.0], [1.0, 2.0, 3.0], np.zeros((2, 2)), np.zeros(0), "ab", None])
def test_step_bad_vectors_raise(bad):
    f = ekf()
    with pytest.raises((ValueError, TypeError)):
        f.step(bad, [0.0, 0.0])
    with pytest.raises((ValueError, TypeError)):
        f.step([0.0, 0.0], bad)
    assert np.all(f.state == 0.0)


@pytest.mark.parametrize("name, bad", [
    ("q", np.eye(3)), ("q", np.zeros((4, 4, 1))), ("q", [1.0, 2.0]), ("r", np.eye(4)), ("r", 1.0),
    ("p0", np.ones(3)), ("x0", [0.0, 0.0]), ("x0", np.zeros((2, 2))), ("x0", np.zeros(5)),
])
def test_constructor_bad_shapes_raise(name, bad):
    with pytest.raises(ValueError, match=name):
        ekf(**{name: bad})


# --- dtypes -----------------------------------------------------------------------------------

# The dtypes numpy casts to float64 under `same_kind` rules. bool is among them (False/True
# read as 0/1, as numpy's own arithmetic does); the others would lose data (complex), parse
# text, or turn dates and objects into numbers, and stay TypeErrors.
ACCEPTED = [np.float64, np.float32, np.float16, np.int64, np.int8, np.uint16, np.longdouble, bool]
REFUSED = [np.complex128, np.complex64, object, "U3", "S3", "datetime64[s]", "timedelta64[ms]",
           [("a", "f8"), ("b", "f8")]]


@pytest.mark.parametrize("dtype", ACCEPTED, ids=str)
def test_real_dtypes_accepted_and_equal_to_float64(dtype):
    u, i = good(40)
    u = (u * 10).astype(dtype)
    i = i.astype(dtype)
    a = ekf().run(u, i)
    b = ekf().run(u.astype(np.float64), i.astype(np.float64))
    np.testing.assert_array_equal(a["theta"], b["theta"])


@pytest.mark.parametrize("dtype", REFUSED, ids=str)
def test_other_dtypes_are_type_errors(dtype):
    f = ekf()
    bad = np.zeros((10, 2), dtype=dtype)
    with pytest.raises(TypeError, match="u_ab"):
        f.run(bad, np.zeros((10, 2)))
    with pytest.raises(TypeError, match="i_ab"):
        f.run(np.zeros((10, 2)), bad)
    with pytest.raises(TypeError):
        ekf(q=np.ones(4, dtype=dtype))
    assert np.all(f.state == 0.0)


def test_object_array_of_numbers_and_lists_and_strings():
    # Python lists are fine; an object array (even of floats) and strings are not.
    u, i = good(20)
    a = ekf().run(u.tolist(), i.tolist())
    np.testing.assert_array_equal(a["theta"], ekf().run(u, i)["theta"])
    with pytest.raises(TypeError):
        ekf().run(u.astype(object), i)
    with pytest.raises(TypeError):
        ekf().run("not an array", i)
    with pytest.raises(TypeError):
        ekf().run(None, i)


# --- layouts ----------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", ["strided", "fortran", "reversed", "readonly", "broadcast", "transposed_view"])
def test_layouts_give_the_same_result(layout):
    u, i = good(60)
    if layout == "strided":
        big_u, big_i = np.zeros((120, 4)), np.zeros((120, 4))
        big_u[::2, 1:3], big_i[::2, ::2] = u, i
        uu, ii = big_u[::2, 1:3], big_i[::2, ::2]
    elif layout == "fortran":
        uu, ii = np.asfortranarray(u), np.asfortranarray(i)
    elif layout == "reversed":
        uu, ii = u[::-1][::-1], i[::-1][::-1]
        uu2 = np.ascontiguousarray(u[::-1])[::-1]
        assert uu2.strides[0] < 0
        uu = uu2
    elif layout == "readonly":
        uu, ii = u.copy(), i.copy()
        uu.setflags(write=False)
        ii.setflags(write=False)
    elif layout == "broadcast":
        u = np.broadcast_to(u[:1], u.shape)
        uu, ii = u, i
    else:
        uu, ii = np.ascontiguousarray(u.T).T, np.ascontiguousarray(i.T).T
    assert not (uu.flags.c_contiguous and ii.flags.c_contiguous and uu.flags.writeable) or layout == "broadcast"
    a = ekf().run(uu, ii)
    b = ekf().run(np.array(u), np.array(i))
    np.testing.assert_array_equal(a["theta"], b["theta"])


# --- non-finite and extreme values -----------------------------------------------------------

@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 1e308, -1e308, 5e-324])
@pytest.mark.parametrize("where", ["u", "i", "both"])
def test_non_finite_and_extreme_samples(value, where):
    u, i = good(100)
    if where in ("u", "both"):
        u[30] = value
    if where in ("i", "both"):
        i[50] = value
    f = ekf()
    out = f.run(u, i)
    assert out["theta"].shape == (100,)
    # The state never becomes non-finite, whatever was rejected.
    assert np.all(np.isfinite(f.state)) and np.all(np.isfinite(f.covariance))
    assert np.all(np.isfinite(out["theta"]))
    if not np.isfinite(value):
        assert pyfoc.Status.REJECTED in out["status"]


# The bounds of ekf-core's "Implausible input" for this servo: |u| up to 20 psi_f / ts = 35 kV,
# |i| up to 100 psi_f / L = 2059 A.
U_MAX, I_MAX = 20 * SERVO["psi_f"] / TS, 100 * SERVO["psi_f"] / SERVO["ls"]


@pytest.mark.parametrize("u_prev, i", [
    ([1e300, 0.0], [0.0, 0.0]), ([0.0, 0.0], [1e300, 0.0]), ([0.0, -1e300], [0.0, 1e300]),
    ([4e4, 0.0], [0.0, 0.0]), ([0.0, 0.0], [0.0, 2.1e3]), ([0.0, 0.0], [0.0, 1e20])])
def test_an_implausible_sample_is_rejected_and_the_state_kept(u_prev, i):
    # REJECTED covers every refused step (docs/python.md, "Errors"): here a finite sample
    # beyond anything a drive applies or a motor carries (a corrupted sample of a log: a real
    # ESC record holds a 670 kV voltage and a 1.4e17 A current). Not an exception: it costs
    # its row, and nothing changes.
    f = ekf()
    f.run(*good(50))
    x, p = f.state, f.covariance
    assert f.step(u_prev, i)["status"] is pyfoc.Status.REJECTED
    np.testing.assert_array_equal(f.state, x)
    np.testing.assert_array_equal(f.covariance, p)
    # In a record: a voltage acts on the next row (run's timing), a current on its own.
    u, i_ab = good(20)
    u[5], i_ab[5] = u_prev, i
    out = f.run(u, i_ab)
    expected = ([5] if np.hypot(*i) > I_MAX else []) + ([6] if np.hypot(*u_prev) > U_MAX else [])
    assert sorted(set(expected)) == np.flatnonzero(out["status"] == pyfoc.Status.REJECTED).tolist()
    assert np.all(np.isfinite(f.state)) and np.all(np.isfinite(f.covariance))


@pytest.mark.parametrize("u_prev, i", [([1e4, 0.0], [0.0, 0.0]), ([0.0, 0.0], [0.0, 1e3])])
def test_a_large_plausible_sample_is_filtered(u_prev, i):
    # Within the bounds above.
    assert np.hypot(*u_prev) < U_MAX and np.hypot(*i) < I_MAX
    f = ekf()
    f.run(*good(50))
    est = f.step(u_prev, i)
    assert est["status"] is not pyfoc.Status.REJECTED
    assert np.all(np.isfinite(f.state)) and np.all(np.isfinite(f.covariance))


def test_all_nan_record():
    f = ekf()
    out = f.run(np.full((20, 2), np.nan), np.full((20, 2), np.nan))
    assert np.all(out["status"] == pyfoc.Status.REJECTED)
    assert np.all(f.state == 0.0)


@pytest.mark.parametrize("u_prev", [[np.nan, 0.0], [np.inf, np.inf]])
def test_non_finite_u_prev(u_prev):
    u, i = good(10)
    out = ekf().run(u, i, u_prev=u_prev)
    assert out["status"][0] == pyfoc.Status.REJECTED
    assert np.all(out["status"][1:] != pyfoc.Status.REJECTED)


@pytest.mark.parametrize("name, value", [
    ("q", [np.nan, 1, 1, 1]), ("q", [np.inf, 1, 1, 1]), ("q", [-1.0, 1, 1, 1]), ("r", [np.nan, 1.0]),
    ("r", [[1.0, 2.0], [0.0, 1.0]]), ("p0", [1, 1, 1, np.inf]), ("x0", [0, 0, np.nan, 0]),
    ("x0", [0, 0, 0, np.inf]),
])
def test_constructor_non_finite_is_config_error(name, value):
    with pytest.raises(pyfoc.ConfigError):
        ekf(**{name: value})


def test_reset_refuses_non_finite_and_bad_shapes():
    f = ekf()
    u, i = good(30)
    f.run(u, i)
    before = (f.state.copy(), f.covariance.copy())
    for x, p in [([0, 0, np.nan, 0], np.eye(4)), ([0, 0, 0, 0], np.full((4, 4), np.inf))]:
        with pytest.raises(pyfoc.FilterError):
            f.reset(x, p)
    for x, p in [([0, 0, 0], np.eye(4)), ([0, 0, 0, 0], np.eye(3)), ("x", np.eye(4))]:
        with pytest.raises((ValueError, TypeError)):
            f.reset(x, p)
    np.testing.assert_array_equal(f.state, before[0])
    np.testing.assert_array_equal(f.covariance, before[1])


# --- empty and huge ---------------------------------------------------------------------------

def test_empty_record_changes_nothing():
    f = ekf()
    out = f.run(np.zeros((0, 2)), np.zeros((0, 2)))
    assert all(v.shape == (0,) for v in out.values())
    assert np.all(f.state == 0.0)
    assert out["status"].dtype == np.int8


@pytest.mark.parametrize("rows", [2**40, 2**61, 2**62 - 1])
def test_huge_arrays_raise_instead_of_aborting(rows):
    # Views that claim terabytes (or more than the address space): a clear MemoryError or
    # ValueError before anything is allocated.
    f = ekf()
    with pytest.raises((MemoryError, ValueError)):
        f.run(huge_view(rows), huge_view(rows))
    with pytest.raises((MemoryError, ValueError)):
        pyfoc.tune_qr(motor(), TS, huge_view(rows), huge_view(rows))
    assert np.all(f.state == 0.0)


def test_huge_simulation_raises_instead_of_aborting():
    # 1e9 periods with a full trace would need about a terabyte.
    with pytest.raises(MemoryError):
        pyfoc.simulate("default", duration=1e5)
    # More than the simulator accepts at all.
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate("default", duration=1e6)


# --- motor and filter parameters -------------------------------------------------------------

BAD_MOTORS = [
    dict(SERVO, rs=-1.0), dict(SERVO, rs=np.nan), dict(SERVO, rs=np.inf), dict(SERVO, ls=0.0),
    dict(SERVO, ls=-1e-3), dict(SERVO, ls=np.inf), dict(SERVO, psi_f=0.0), dict(SERVO, psi_f=np.nan),
    dict(SERVO, pole_pairs=0), dict(SERVO, pole_pairs=-1), dict(SERVO, pole_pairs=2**40),
    dict(SERVO, ld=np.nan), dict(SERVO, lq=-1.0), dict(SERVO, ld=0.0),
]


@pytest.mark.parametrize("kw", BAD_MOTORS, ids=lambda kw: ",".join(f"{k}={v}" for k, v in kw.items() if v != SERVO.get(k)))
def test_bad_motor_parameters_are_config_errors(kw):
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.Motor(**kw)


@pytest.mark.parametrize("kw", [dict(SERVO, pole_pairs=4.5), dict(SERVO, rs="2.8"), dict(SERVO, ls=None),
                                dict(SERVO, pole_pairs=2**80)])
def test_wrong_motor_types_raise(kw):
    with pytest.raises((TypeError, OverflowError, pyfoc.ConfigError)):
        pyfoc.Motor(**kw)


@pytest.mark.parametrize("ts", [0.0, -1e-4, np.nan, np.inf, 1e-300])
def test_bad_ts_is_config_error(ts):
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.Ekf(motor(), ts)


@pytest.mark.parametrize("kw", [dict(rs=1e300, ls=1e-300, psi_f=1e300, pole_pairs=1),
                                dict(rs=1e-300, ls=1e300, psi_f=1e-300, pole_pairs=1),
                                dict(rs=1e-12, ls=1e-12, psi_f=1e-12, pole_pairs=2**31)])
@pytest.mark.parametrize("ts", [1e-4, 1e3])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_extreme_but_valid_parameters_give_results_or_errors(kw, ts, dtype):
    try:
        f = pyfoc.Ekf(pyfoc.Motor(**kw), ts, dtype=dtype)
    except pyfoc.ConfigError:
        return
    u, i = good(30)
    out = f.run(u * 1e3, i)
    assert out["theta"].shape == (30,)
    assert np.all(np.isfinite(f.state))


def test_wrong_argument_types_raise():
    with pytest.raises(TypeError):
        pyfoc.Ekf("servo", TS)
    with pytest.raises(TypeError):
        pyfoc.Ekf(motor(), "1e-4")
    with pytest.raises(pyfoc.ConfigError):
        ekf(dtype="complex128")
    with pytest.raises(TypeError):
        ekf(dtype=None)


# --- threads ----------------------------------------------------------------------------------

def test_one_shared_ekf_from_many_threads():
    """Concurrent calls on one Ekf are serialized (a lock, taken without the GIL): every call
    returns, nothing raises, and N runs of a record equal one run of the record N times."""
    u, i = good(5000)
    shared = ekf()
    errors, outs = [], []
    barrier = threading.Barrier(6)

    def runner():
        try:
            barrier.wait()
            outs.append(shared.run(u, i)["theta"][-1])
        except Exception as e:  # noqa: BLE001 - collected and asserted below
            errors.append(e)

    def poker():
        try:
            barrier.wait()
            for _ in range(200):
                assert shared.state.shape == (4,)
                assert shared.covariance.shape == (4, 4)
                shared.u_last  # noqa: B018
                shared.step([0.0, 0.0], [0.0, 0.0])
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    run_threads(*[runner] * 4, *[poker] * 2)
    assert not errors, errors
    assert len(outs) == 4
    assert np.all(np.isfinite(shared.state))


def test_serialized_runs_equal_sequential_runs():
    u, i = good(3000)
    shared = ekf()
    run_threads(*[lambda: shared.run(u, i)] * 3)
    seq = ekf()
    for _ in range(3):
        seq.run(u, i)
    np.testing.assert_array_equal(shared.state, seq.state)


def test_gil_is_released_during_run():
    """While one thread runs a long record, another thread keeps executing Python: it ticks
    during the last 70 % of the call (the filter loop; converting the inputs comes first)."""
    import time

    u, i = good(400_000)
    f = ekf()
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(time.perf_counter())

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.01)
    try:
        t0 = time.perf_counter()
        f.run(u, i)
        t1 = time.perf_counter()
    finally:
        done.set()
        t.join()
    late = [x for x in ticks if t0 + 0.3 * (t1 - t0) <= x <= t1]
    assert len(late) > 10, (len(late), t1 - t0)


def test_many_threads_many_filters_and_tuners():
    u, i = good(2000)
    results, errors = [], []

    def work(k):
        try:
            if k % 2:
                results.append(ekf(dtype="float32").run(u, i)["theta"][-1])
            else:
                results.append(pyfoc.tune_qr(motor(), TS, u, i, skip=100, max_evals=20)["mean_nis_after"])
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    run_threads(*[lambda k=k: work(k) for k in range(8)])
    assert not errors and len(results) == 8


# --- simulate() with malformed dicts and paths -----------------------------------------------

SCENARIOS = os.path.join(os.path.dirname(__file__), "..", "..", "pmsm-sim", "scenarios")


def scenario_dict():
    import tomllib

    with open(os.path.join(SCENARIOS, "servo-ideal.toml"), "rb") as f:
        return tomllib.load(f)


def mutate(path, value):
    def f(d):
        node = d
        for key in path[:-1]:
            node = node[key]
        if value is KeyError:
            del node[path[-1]]
        else:
            node[path[-1]] = value
        return d
    return f


MALFORMED = [
    mutate(("motor",), "not a table"),
    mutate(("motor", "rs_ohm"), "2.8"),
    mutate(("motor", "rs_ohm"), float("nan")),
    mutate(("motor", "rs_ohm"), float("inf")),
    mutate(("motor", "rs_ohm"), -1.0),
    mutate(("motor", "pole_pairs"), -4),
    mutate(("motor", "pole_pairs"), 2**70),
    mutate(("motor", "catalog"), KeyError),  # the motor's values then missing
    mutate(("inverter", "ts_s"), 0.0),
    mutate(("inverter", "ts_s"), 1e-300),
    mutate(("duration_s",), -1.0),
    mutate(("duration_s",), None),
    mutate(("speed_ref_rpm", "points"), [[0.0, float("nan")]]),
    mutate(("speed_ref_rpm", "points"), [[0.0]]),
    mutate(("speed_ref_rpm", "points"), [[1.0, 0.0], [0.5, 1.0]]),
    mutate(("sensors", "adc_bits"), 99),
    mutate(("load",), [{"kind": "wind"}]),
    mutate(("controller", "kind"), "telepathy"),
    mutate(("name",), ""),
    mutate(("extra",), {"x": 1}),
    lambda d: {},
    lambda d: {"name": "x"},
]


@pytest.mark.parametrize("fn", MALFORMED)
def test_malformed_scenario_dicts_are_config_errors(fn):
    d = fn(scenario_dict())
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(d, duration=0.01)


@pytest.mark.parametrize("path, value, key, problem", [
    # The messages of a TOML file (tests/cli.rs), without its line and column.
    (("motor", "pole_pairs"), "four", "motor.pole_pairs",
     'expected a whole number >= 0, got the string "four"'),
    (("motor", "pole_pairs"), 2.5, "motor.pole_pairs",
     "expected a whole number >= 0, got the number 2.5"),
    (("inverter", "ts_s"), "fast", "inverter.ts_s", 'expected a number, got the string "fast"'),
    (("controller", "foc", "if_current_a"), [1.0], "controller.foc.if_current_a",
     "expected a number, got an array"),
    # (a load term is read whole, by its kind: a file names it as load[0] too)
    (("load", 0, "after_nm"), "1.5", "load[0]", 'expected a number, got the string "1.5"'),
    (("speed_ref_rpm", "points"), "ramp", "speed_ref_rpm.points", "ramp"),
    (("duration_s",), None, "duration_s", ""),
    # Values refused by the validation name their key and the allowed range.
    (("load", 0, "after_nm"), 1e300, "load[0].after_nm", "allowed"),
    (("initial", "speed_rpm"), 1e300, "initial.speed_rpm", "allowed"),
])
def test_dict_errors_name_the_key_path_as_toml_does(path, value, key, problem):
    d = mutate(path, value)(scenario_dict())
    with pytest.raises(pyfoc.ConfigError) as e:
        pyfoc.simulate(d, duration=0.01)
    text = str(e.value)
    assert text.startswith(f"scenario dict: {key}: "), text
    assert problem in text, text


@pytest.mark.parametrize("bad", [
    {"motor": {1, 2}},  # not JSON-serializable
    {"motor": np.zeros(3)},
    {1: 2},
])
def test_unserializable_scenario_dicts_raise(bad):
    with pytest.raises((TypeError, ValueError)):
        pyfoc.simulate(bad)


def test_recursive_and_deep_dicts_raise():
    d = scenario_dict()
    d["motor"]["self"] = d
    with pytest.raises((ValueError, RecursionError)):
        pyfoc.simulate(d)
    # Inside an internally tagged enum (a load term), serde buffers the whole value: without
    # the nesting limit this would recurse until the stack overflows.
    d = scenario_dict()
    d["load"] = [{"kind": "step", "extra": d}]
    with pytest.raises(ValueError):
        pyfoc.simulate(d)
    deep = {}
    node = deep
    for _ in range(10_000):
        node["x"] = {}
        node = node["x"]
    with pytest.raises((ValueError, RecursionError)):
        pyfoc.simulate(deep)


def test_malformed_paths(tmp_path):
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(str(tmp_path))  # a directory
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(tmp_path / "missing.toml")
    p = tmp_path / "garbage.toml"
    p.write_bytes(b"\xff\xfe not utf-8 \x00\x01")
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(p)
    p = tmp_path / "bad.toml"
    p.write_text("name = [unclosed\n")
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(p)
    p.write_text("")
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate(p)
    with pytest.raises((pyfoc.ConfigError, ValueError)):
        pyfoc.simulate("nul\x00byte")
    with pytest.raises(TypeError):
        pyfoc.simulate(b"default")
    with pytest.raises(TypeError):
        pyfoc.simulate(3.5)
    with pytest.raises(TypeError):
        pyfoc.simulate(["default"])


@pytest.mark.parametrize("kw", [dict(duration=0.0), dict(duration=float("nan")), dict(duration=-float("inf")),
                                dict(duration=1e-9)])
def test_bad_simulate_durations(kw):
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.simulate("default", **kw)


@pytest.mark.parametrize("seed", [-1, 2**64, 1.5, "1"])
def test_bad_seeds(seed):
    with pytest.raises((TypeError, OverflowError, ValueError)):
        pyfoc.simulate("default", duration=0.01, seed=seed)


def test_bad_mcap_paths(tmp_path):
    with pytest.raises(pyfoc.PyfocError):
        pyfoc.simulate("default", duration=0.01, mcap=tmp_path / "no" / "such" / "dir" / "x.mcap")
    with pytest.raises(TypeError):
        pyfoc.simulate("default", duration=0.01, mcap=5)


@pytest.mark.parametrize("content", [b"", b"garbage", b"\x89MCAP0\r\n" + b"\x00" * 40])
def test_tune_qr_mcap_on_bad_files(tmp_path, content):
    p = tmp_path / "x.mcap"
    p.write_bytes(content)
    with pytest.raises(pyfoc.PyfocError, match="x.mcap"):
        pyfoc.tune_qr_mcap(p)
    with pytest.raises(pyfoc.PyfocError):
        pyfoc.tune_qr_mcap(tmp_path / "missing.mcap")
    with pytest.raises(TypeError):
        pyfoc.tune_qr_mcap(None)


def test_nan_in_truth_and_tuner_options():
    u, i = good(1000)
    with pytest.raises(ValueError):
        pyfoc.tune_qr(motor(), TS, u, i[:-1])
    with pytest.raises(ValueError):
        pyfoc.tune_qr(motor(), TS, u, i, theta_true=np.zeros(3))
    with pytest.raises(ValueError):
        pyfoc.tune_qr(motor(), TS, u, i, max_evals=0)
    with pytest.raises(ValueError):
        pyfoc.tune_qr(motor(), TS, u, i, r_shape="diagonal")
    with pytest.raises(ValueError):
        pyfoc.tune_qr(motor(), TS, u[:100], i[:100])
    with pytest.raises(ValueError, match="skip must be >= 0"):
        pyfoc.tune_qr(motor(), TS, u, i, skip=-1)
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.tune_qr(motor(), math.nan, u, i)
    # NaN rows are rejected samples, not a failure.
    i2 = i.copy()
    i2[500] = np.nan
    rep = pyfoc.tune_qr(motor(), TS, u, i2, skip=100, max_evals=20)
    assert rep["samples_rejected"] == 1


def _servo():
    return pyfoc.Motor(2.875, 8.5e-3, 0.175, 4)


@pytest.mark.parametrize(
    "p, words",
    [
        (-np.eye(4), "positive semi-definite"),
        (np.eye(4) + np.triu(np.ones((4, 4)), 1), "symmetric"),
        (np.eye(4) * 1e300, "entry above"),
    ],
)
def test_reset_applies_the_constructors_covariance_check(p, words):
    ekf = pyfoc.Ekf(_servo(), 1e-4)
    before = ekf.state.copy()
    with pytest.raises(pyfoc.ConfigError, match=words):
        ekf.reset(np.zeros(4), p)
    assert np.array_equal(ekf.state, before)


def test_sample_time_out_of_range_is_named():
    with pytest.raises(pyfoc.ConfigError, match=r"ts_s is outside its accepted range \[1e-7, 1\] s"):
        pyfoc.Ekf(_servo(), 1e-300)


@pytest.mark.parametrize("arg", ["q", "p0"])
def test_absurd_covariances_are_refused(arg):
    with pytest.raises(pyfoc.ConfigError, match="entry above"):
        pyfoc.Ekf(_servo(), 1e-4, **{arg: np.eye(4) * 1e300})


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: pyfoc.suite(seed=-1), "seed"),
        (lambda: pyfoc.simulate("default", duration=0.01, seed=-3), "seed"),
        (lambda: pyfoc.identify("default", seed=-1), "seed"),
        (lambda: pyfoc.tune_qr_mcap("nonexistent.mcap", skip=-1), "skip"),
        (lambda: pyfoc.tune_qr_mcap("nonexistent.mcap", max_evals=-5), "max_evals"),
    ],
)
def test_negative_counts_name_the_argument(call, name):
    with pytest.raises(ValueError, match=name + " must be >= 0"):
        call()


def test_non_integer_count_names_the_argument():
    with pytest.raises(TypeError, match="seed must be an integer"):
        pyfoc.suite(seed=1.5)

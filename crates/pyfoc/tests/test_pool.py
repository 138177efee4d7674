"""The buffer pool of `Ekf.run`: a fresh result's arrays are the last result's memory when
nothing refers to that result any more. Reused arrays must give the same numbers as a run into
the caller's own `out=` arrays (which never touches the pool), and a result, or any view of
it, that is still alive must never be written by a later call."""
import gc
import warnings

import numpy as np
import pytest

import pyfoc
from test_api import SERVO, record, run_threads

LONG = 100_000  # pipelined (>= 2^16 rows) and pooled
SHORT = 30_000  # sequential path


def make(dtype="float64"):
    return pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=1e-4, dtype=dtype)


def reference(u, i, dtype="float64"):
    """The result of a new filter on (u, i), written into arrays owned by the test."""
    n = len(u)
    out = {k: np.full(n, np.nan) for k in ["theta", "omega", "omega_mech", "i_alpha", "i_beta",
                                            "nis", "psi_f", "rs", "winding_temperature"]}
    out["status"] = np.full(n, -1, dtype=np.int8)
    make(dtype).run(u, i, out=out)
    return out


def assert_equal(got, want):
    assert set(got) == set(want)
    for k, v in want.items():
        assert got[k].shape == v.shape and got[k].dtype == v.dtype, k
        np.testing.assert_array_equal(got[k], v, err_msg=k)


def address(result):
    return result["theta"].__array_interface__["data"][0]


@pytest.fixture(autouse=True)
def empty_pool():
    pyfoc.clear_buffer_pool()
    yield
    pyfoc.clear_buffer_pool()


def test_dropped_result_is_reused_and_results_are_identical():
    u, i, _ = record(LONG)
    want = reference(u, i)
    first = make().run(u, i)
    assert_equal(first, want)
    addr = address(first)
    del first
    second = make().run(u, i)
    assert address(second) == addr  # the same memory, no fresh pages
    assert_equal(second, want)
    # Columns are still separate rows: writing one leaves the others.
    before = second["omega"].copy()
    second["theta"][:] = 0.0
    np.testing.assert_array_equal(second["omega"], before)
    del second
    # Reused arrays can be a later call's out=; a streamed record equals one call.
    ekf = make()
    out = ekf.run(u[:LONG // 2], i[:LONG // 2])
    ekf.run(u[LONG // 2:], i[LONG // 2:], out=out)
    for k, v in want.items():
        np.testing.assert_array_equal(out[k], v[LONG // 2:], err_msg=k)


def test_kept_results_and_views_are_never_overwritten():
    u, i, _ = record(LONG)
    u2, i2, _ = record(LONG, w=300.0, seed=5)
    want, want2 = reference(u, i), reference(u2, i2)
    kept = make().run(u, i)
    snapshot = {k: v.copy() for k, v in kept.items()}
    # Views, slices, a memoryview and a lone column of other results, their dicts dropped.
    r = make().run(u, i)
    omega_part, status_every_other = r["omega"][10:2000], r["status"][::2]
    r2 = make().run(u, i)
    mv = memoryview(r2["nis"])
    r3 = make().run(u, i)
    lone_status = r3["status"]
    r4 = make().run(u, i)
    base = r4["rs"].base
    del r, r2, r3, r4
    gc.collect()
    alive = [*kept.values(), omega_part, status_every_other, np.asarray(mv), lone_status, base]
    for _ in range(3):
        new = make().run(u2, i2)
        assert_equal(new, want2)
        assert not any(np.shares_memory(x, y) for x in new.values() for y in alive)
        del new
    assert_equal(kept, snapshot)
    np.testing.assert_array_equal(omega_part, want["omega"][10:2000])
    np.testing.assert_array_equal(status_every_other, want["status"][::2])
    np.testing.assert_array_equal(np.asarray(mv), want["nis"])
    np.testing.assert_array_equal(lone_status, want["status"])
    np.testing.assert_array_equal(base[7], want["rs"])
    # Once dropped, a result's memory may serve the next call.
    last = make().run(u2, i2)
    addr = address(last)
    del last
    assert address(make().run(u, i)) == addr


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_sizes_and_precisions(dtype):
    """Longer pooled arrays serve shorter runs (down to half their length) as views of their
    first N values; other sizes get new arrays; both precisions share the float64 outputs."""
    u, i, _ = record(200_000, seed=3)
    for n in [LONG, 70_000, 51_000, SHORT, SHORT, 1, 0, 200_000, 120_000, LONG, 3]:
        for prec in [dtype, "float64" if dtype == "float32" else "float32"]:
            got = make(prec).run(u[:n], i[:n])
            assert_equal(got, reference(u[:n], i[:n], prec))
            for v in got.values():
                assert v.flags.c_contiguous and v.flags.writeable and v.shape == (n,)
            if n:
                assert got["theta"].base is got["rs"].base
                assert got["theta"].base.shape[1] >= n
            del got


def test_results_changed_in_place_before_being_dropped():
    """A caller may freeze, reshape or retype a result's arrays in place before dropping
    them: the next call then allocates new arrays, with the right numbers."""
    u, i, _ = record(LONG)
    want = reference(u, i)
    for change in [
        lambda base, status: base.setflags(write=False),
        lambda base, status: status.setflags(write=False),
        lambda base, status: setattr(base, "shape", (9 * LONG,)),
        lambda base, status: setattr(base, "dtype", np.int64),
        lambda base, status: setattr(status, "dtype", np.uint8),
    ]:
        r = make().run(u, i)
        base, status = r["theta"].base, r["status"]
        del r
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            change(base, status)
        del base, status
        got = make().run(u, i)
        assert_equal(got, want)
        assert all(v.flags.writeable for v in got.values())
        assert got["theta"].base.shape == (9, LONG) and got["theta"].base.dtype == np.float64
        del got


def test_clear_buffer_pool():
    u, i, _ = record(LONG)
    want = reference(u, i)
    kept = make().run(u, i)
    # The pool holds the result's arrays (73 bytes a row) and the input copies' blocks.
    held = pyfoc.clear_buffer_pool()
    assert held >= 73 * LONG + 32 * LONG
    assert pyfoc.clear_buffer_pool() == 0
    assert_equal(kept, want)
    del kept
    again = make().run(u, i)
    assert_equal(again, want)
    assert pyfoc.clear_buffer_pool() > 0


def test_huge_results_are_not_pooled():
    """Outputs over the pool's 256 MiB (3.6 million rows) are not kept after the call."""
    n = 3_800_000
    u = np.broadcast_to(np.array([1.0, 0.0]), (n, 2))
    r = make().run(u, u)
    assert r["theta"].shape == (n,)
    del r
    # Only input copies (32 bytes a row, at most 128 MiB) remain.
    assert pyfoc.clear_buffer_pool() <= 128 << 20


def test_threads_sharing_the_pool():
    """Several threads run, keep and drop results at once: each equals its reference."""
    recs = [record(70_000, w=200.0 + 100 * k, seed=k) for k in range(4)]
    wants = [reference(u, i) for u, i, _ in recs]
    errors = []

    def work(k):
        try:
            u, i, _ = recs[k]
            kept = []
            for j in range(6):
                r = make().run(u, i)
                assert_equal(r, wants[k])
                if j % 2:
                    kept.append(r)
                del r
            for r in kept:
                assert_equal(r, wants[k])
        except Exception as e:  # noqa: BLE001 - collected and asserted below
            errors.append(e)

    run_threads(*[lambda k=k: work(k) for k in range(4)])
    assert not errors, errors

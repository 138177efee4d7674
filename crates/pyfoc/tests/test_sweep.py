"""pyfoc.sweep: the plan's values reach the runs, a table is the same whatever the executor
(the default process pool, threads, a Dask LocalCluster), a failing run is a row with its
error, malformed plans are refused by name."""
import concurrent.futures as cf
import math

import polars as pl
import pytest
from polars.testing import assert_frame_equal

import pyfoc

# Short runs: the default drive for 0.3 s (standstill, alignment, I/f ramp, hand-over).
VARY = {
    "duration_s": 0.3,
    "motor.rs_ohm": ("uniform", 2.5, 3.2),
    "inverter.dead_time_s": [0.0, 1e-6],
}


@pytest.fixture(scope="module")
def local():
    return pyfoc.sweep("default", VARY, n=3, seed=5)


def test_columns_rows_and_values(local):
    df = local
    assert df.height == 6
    assert df.columns[:5] == ["index", "duration_s", "inverter.dead_time_s", "motor.rs_ohm", "seed"]
    assert df.columns[-1] == "error"
    assert df["index"].to_list() == list(range(6))
    # The grid axis varies slowest-last over the 3 draws each; the draws are in range and new.
    assert df["inverter.dead_time_s"].to_list() == [0.0] * 3 + [1e-6] * 3
    rs = df["motor.rs_ohm"].to_list()
    assert all(2.5 <= r < 3.2 for r in rs) and len(set(rs)) == 6
    assert df["seed"].n_unique() == 6
    assert df["error"].null_count() == 6
    # The runs ran the plan: 0.3 s each, and the metrics are the simulator's.
    assert df["simulated_s"].to_list() == [0.3] * 6
    assert df["periods"].to_list() == [3000] * 6
    assert df.schema["observer.angle_error_rms_deg"] == pl.Float64
    assert all(math.isfinite(x) for x in df["observer.angle_error_rms_deg"])
    assert df["end"].to_list() == ["completed"] * 6
    assert "wall_time_s" not in df.columns and "real_time_factor" not in df.columns


def _default_dict():
    """The default scenario as a dict (its TOML through the sweep plan's first run)."""
    import tomllib

    _, runs = pyfoc._native._sweep_plan("default", {}, 1, 0)
    return tomllib.loads(runs[0][3])


def test_a_run_is_the_scenario_with_the_values():
    """A sweep run equals pyfoc.simulate of the scenario with the run's values and seed."""
    base = _default_dict()
    df = pyfoc.sweep(base, {"duration_s": [0.2], "motor.rs_ohm": ("relative", 0.1)}, n=2, seed=9,
                     executor=cf.ThreadPoolExecutor(2))
    for row in df.iter_rows(named=True):
        sc = {**base, "duration_s": 0.2, "motor": {**base["motor"], "rs_ohm": row["motor.rs_ohm"]}}
        m = pyfoc.simulate(sc, seed=row["seed"])["metrics"]
        assert row["observer.angle_error_rms_deg"] == m["observer"]["angle_error_rms_deg"]
        assert row["drive.peak_current_a"] == m["drive"]["peak_current_a"]
    assert df["motor.rs_ohm"].n_unique() == 2


def test_same_table_with_threads_and_dask(local):
    with cf.ThreadPoolExecutor(max_workers=2) as ex:
        threads = pyfoc.sweep("default", VARY, n=3, seed=5, executor=ex, chunk_size=1)
    assert_frame_equal(threads, local)
    from distributed import Client, LocalCluster

    with LocalCluster(processes=False, n_workers=2, threads_per_worker=1,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        dask = pyfoc.sweep("default", VARY, n=3, seed=5, executor=client.get_executor())
    assert_frame_equal(dask, local)
    other = pyfoc.sweep("default", VARY, n=3, seed=6, executor=cf.ThreadPoolExecutor(2))
    assert other["motor.rs_ohm"].to_list() != local["motor.rs_ohm"].to_list()


class _RayExecutor(cf.Executor):
    """Ray tasks behind the concurrent.futures interface pyfoc.sweep takes: ``submit`` runs
    ``fn`` as a Ray task and returns its ObjectRef's ``future()`` (Ray has no
    concurrent.futures Executor of its own)."""

    def __init__(self, ray):
        self._ray = ray

    def submit(self, fn, /, *args, **kwargs):
        return self._ray.remote(fn).remote(*args, **kwargs).future()


def test_same_table_with_ray(local):
    """Ray on this machine (a local cluster of 2 CPUs) gives the same table as the default
    process pool. Optional: runs only where ``ray`` is importable (it is not in
    tests/data/requirements.txt: about 240 MB installed)."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        df = pyfoc.sweep("default", VARY, n=3, seed=5, executor=_RayExecutor(ray))
    finally:
        ray.shutdown()
    assert_frame_equal(df, local)


def test_a_failing_run_is_a_row():
    df = pyfoc.sweep("default", {"duration_s": 0.1, "controller.current_limit_a": [4.5, -1.0]},
                     executor=cf.ThreadPoolExecutor(2))
    assert df.height == 2
    ok, bad = df.row(0, named=True), df.row(1, named=True)
    assert ok["error"] is None and ok["end"] == "completed"
    assert "controller.current_limit_a" in bad["error"]
    assert bad["end"] is None and bad["observer.angle_error_rms_deg"] is None


class LosingExecutor(cf.Executor):
    """Every other task's worker is lost: its future raises."""

    def __init__(self):
        self.k = 0

    def submit(self, fn, *args, **kwargs):
        f = cf.Future()
        self.k += 1
        if self.k % 2:
            f.set_exception(RuntimeError("worker lost"))
        else:
            f.set_result(fn(*args, **kwargs))
        return f


def test_a_lost_task_is_rows_with_its_error():
    df = pyfoc.sweep("default", {"duration_s": [0.05, 0.1, 0.15]}, executor=LosingExecutor(),
                     chunk_size=1)
    assert df["error"].to_list() == ["RuntimeError: worker lost", None, "RuntimeError: worker lost"]
    assert df["simulated_s"].to_list()[1] == 0.1


@pytest.mark.parametrize("vary, n, match", [
    ({"motor.rs_ohm": ("uniform", 3.0)}, 1, r"vary\.motor\.rs_ohm: expected"),
    ({"motor.rs_ohm": ("gaussian", 3.0, 0.1)}, 1, r"vary\.motor\.rs_ohm: a tuple is a distribution"),
    ({"motor.rs_ohm": ("uniform", 3.0, 2.0)}, 1, "out of order"),
    ({"motor.rs_ohm.x": [1.0]}, 1, "motor.rs_ohm is a value"),
    ({"motor.rs_ohm": []}, 1, "empty list"),
    ({"motor.rs_ohm": [None]}, 1, r"vary\.motor\.rs_ohm"),
    ({}, 0, "n must be"),
])
def test_bad_plans_are_refused(vary, n, match):
    with pytest.raises(pyfoc.ConfigError, match=match):
        pyfoc.sweep("default", vary, n=n)

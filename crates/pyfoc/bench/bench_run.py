"""Throughput of pyfoc.Ekf.run (10^6 samples) and filterpy's ExtendedKalmanFilter (10^4
samples) on the same seed filter, side by side. Prints samples per second and the ratio.

    python crates/pyfoc/bench/bench_run.py      (inside the venv with pyfoc and filterpy)

Medians over repeats (pyfoc 5 x 10^6, filterpy 3 x 10^4). The last column is the per-call
overhead of `run` (input checks and copies, output arrays, lock, GIL release): its time over
that of the observer's own steps on the same rows, median of the per-repeat ratios.
"""
import os
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # numpy threads would compete with the timed loop
import statistics
import sys
import time
import pathlib

import numpy as np

import pyfoc
from pyfoc._bench import time_steps

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from test_filterpy import SeedEkf, H, wrap  # noqa: E402

SERVO = dict(rs=2.875, ls=8.5e-3, psi_f=0.175, pole_pairs=4)
TS = 1e-4
# The filter foc and the simulator run; `Ekf`'s defaults add the acceleration feedforward and
# the online input calibration (for recorded drives).
FIRMWARE = dict(acceleration_feedforward=False, input_calibration=False)


def make(n, seed=0):
    rng = np.random.default_rng(seed)
    th = 0.1 * np.arange(n)
    i_ab = np.column_stack([-2 * np.sin(th), 2 * np.cos(th)]) + 0.01 * rng.standard_normal((n, 2))
    u_ab = np.column_stack([-180 * np.sin(th), 180 * np.cos(th)])
    return u_ab, i_ab


def time_pyfoc(n, chunk=None, **kw):
    """Samples per second of `Ekf.run`, and the median over the repeats of the ratio of its
    time to that of the observer's own steps on the same rows (`pyfoc._bench.time_steps`: the
    loop of `run` without its input checks and copies and without its output arrays), timed
    alternately so that both see the same machine.

    `chunk`: the record is filtered in calls of `chunk` rows, each writing into the arrays of
    the first call (`out=`), as a user streaming a long record does; the first call, which
    allocates them, is not timed."""
    u, i = make(n)
    times, ratios = [], []
    for _ in range(5):
        core = time_steps(pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=TS, **kw), u, i)
        ekf = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=TS, **kw)
        if chunk is None:
            t0 = time.perf_counter()
            ekf.run(u, i)
        else:
            out = pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=TS, **kw).run(u[:chunk], i[:chunk])
            t0 = time.perf_counter()
            for a in range(0, n, chunk):
                ekf.run(u[a:a + chunk], i[a:a + chunk], out=out)
        times.append(time.perf_counter() - t0)
        ratios.append(times[-1] / core)
    return n / statistics.median(times), statistics.median(ratios)


def time_filterpy(n):
    u, i = make(n)
    times = []
    for _ in range(3):
        f = SeedEkf(SERVO["rs"], SERVO["ls"], SERVO["psi_f"], TS)
        f.x = np.zeros(4)
        f.P = np.diag([1.0, 1.0, 100.0, 1.0])
        f.Q = np.diag([0.01, 0.01, 10.0, 0.01])
        f.R = np.diag([0.1, 0.1])
        u_prev = np.zeros(2)
        t0 = time.perf_counter()
        for k in range(n):
            f.F = f.jacobian()
            f.predict(u=u_prev)
            f.x[3] = wrap(f.x[3])
            f.update(i[k], HJacobian=lambda x: H, Hx=lambda x: H @ x)
            f.x[3] = wrap(f.x[3])
            u_prev = u[k]
        times.append(time.perf_counter() - t0)
    return n / statistics.median(times)


def main():
    fp = time_filterpy(10_000)
    rows = [
        ("pyfoc f64 defaults (recorded drives)", time_pyfoc(1_000_000)),
        ("pyfoc f64 firmware's filter (lag-free, Joseph)", time_pyfoc(1_000_000, **FIRMWARE)),
        ("pyfoc f64 seed (forward Euler, standard)", time_pyfoc(
            1_000_000, discretization="forward_euler", covariance_update="standard",
            q=[0.01, 0.01, 10.0, 0.01], r=[0.1, 0.1], **FIRMWARE)),
        ("pyfoc f32 firmware's filter", time_pyfoc(1_000_000, dtype="float32", **FIRMWARE)),
        ("pyfoc f64 firmware's, 10 chunks into out=", time_pyfoc(
            1_000_000, chunk=100_000, **FIRMWARE)),
        ("pyfoc f32 firmware's, 10 chunks into out=", time_pyfoc(
            1_000_000, chunk=100_000, dtype="float32", **FIRMWARE)),
    ]
    print(f"{'filter':45} {'samples/s':>14} {'x filterpy':>11} {'run / steps':>12}")
    print(f"{'filterpy ExtendedKalmanFilter (seed)':45} {fp:14,.0f} {1.0:11.1f} {'-':>12}")
    for name, (rate, ratio) in rows:
        print(f"{name:45} {rate:14,.0f} {rate / fp:11.1f} {ratio:12.3f}")


if __name__ == "__main__":
    main()

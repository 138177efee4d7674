"""CPU cost of pyfoc.Ekf.run (10^6 rows) over the observer's own steps, measured so that the
machine's load enters as little as possible (bench_run.py's wall-clock ratio moves with it).

    python crates/pyfoc/bench/bench_cpu.py [LABEL]     (inside the venv with pyfoc)

Per configuration, 9 calls, each after a `pyfoc._bench.time_steps` on the same rows; a call's
result is dropped before the next (as in bench_run.py, so `run` may reuse its buffers). Columns:
`thread`: CPU time of the calling thread, on which the filter runs (`time.thread_time`), over
the steps' time (the fastest of the 9 `time_steps`: preemption only lengthens it), min and
median over the calls; `all`: CPU time of every thread of the process (`getrusage`: the
helper thread that copies the inputs included) over the steps' time, median of the last 8
calls; `sys`: the kernel's part of it per call (page faults, zeroing fresh memory); `minflt`:
minor page faults per call. With a free second core the wall-clock ratio approaches `thread`;
with none it approaches `all`. The last row streams the record in 10 chunks into `out=`.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import pathlib  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import pyfoc  # noqa: E402
from pyfoc._bench import time_steps  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_run import FIRMWARE, SERVO, TS, make  # noqa: E402

CONFIGS = [
    ("f64 defaults", {}, None),
    ("f64 firmware's", FIRMWARE, None),
    ("f64 seed", dict(discretization="forward_euler", covariance_update="standard",
                      q=[0.01, 0.01, 10.0, 0.01], r=[0.1, 0.1], **FIRMWARE), None),
    ("f32 firmware's", dict(dtype="float32", **FIRMWARE), None),
    ("f64 firmware's, 10 chunks out=", FIRMWARE, 100_000),
]


def main():
    label = sys.argv[1] if len(sys.argv) > 1 else ""
    u, i = make(1_000_000)
    print(f"{label:8} {'filter':20} {'thread min':>10} {'median':>7} {'all':>6} {'steps ms':>9} "
          f"{'sys ms':>7} {'minflt':>7}")
    for name, kw, chunk in CONFIGS:
        def new():
            return pyfoc.Ekf(pyfoc.Motor(**SERVO), ts=TS, **kw)
        out = new().run(u[:chunk], i[:chunk]) if chunk else None
        steps, thread, cpu, kernel, faults = [], [], [], [], []
        for _ in range(9):
            steps.append(time_steps(new(), u, i))
            ekf = new()
            r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.thread_time()
            if chunk:
                for a in range(0, len(u), chunk):
                    ekf.run(u[a:a + chunk], i[a:a + chunk], out=out)
            else:
                ekf.run(u, i)
            t1, r1 = time.thread_time(), resource.getrusage(resource.RUSAGE_SELF)
            thread.append(t1 - t0)
            cpu.append(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime)
            kernel.append(r1.ru_stime - r0.ru_stime)
            faults.append(r1.ru_minflt - r0.ru_minflt)
        s = min(steps)
        print(f"{label:8} {name:20} {min(thread) / s:10.3f} {statistics.median(thread) / s:7.3f} "
              f"{statistics.median(cpu[1:]) / s:6.3f} {s * 1e3:9.1f} "
              f"{statistics.median(kernel[1:]) * 1e3:7.1f} {statistics.median(faults[1:]):7.0f}")


if __name__ == "__main__":
    main()

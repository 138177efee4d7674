"""Throughput of pyfoc.sweep against one core, and the lock-loss sweep of the default drive.

    python crates/pyfoc/bench/bench_sweep.py [--runs 1000] [--duration SECONDS]

1. Single-run speed: the default scenario run one after another in this process (the native
   run of a sweep, `_sweep_run`), runs per second.
2. The same runs through `pyfoc.sweep` with its default executor (a process pool over the
   cores): runs per second, and its ratio to cores x the single-run speed (goal >= 0.9).
3. The lock-loss sweep: `--runs` runs of the default drive with parameter errors of the
   drive's model (the observers' and foc's Rs +-30 %, L +-20 %, psi_f +-10 %, uniform), the dead
   time 0-2 us and the ADC noise x0.5-x3; wall time and the share of runs that lost the
   lock (left closed loop, tripped, or stopped early).

On a shared machine, other processes take cores from the sweep: the load average is printed;
the 1-process pool against one core, and the workers' CPU time against that of the runs alone
(one after another), measure the sweep's own overhead whatever the load.
"""
import argparse
import concurrent.futures as cf
import os
import resource
import time
import tomllib

import pyfoc

p = argparse.ArgumentParser()
p.add_argument("--runs", type=int, default=1000)
p.add_argument("--duration", type=float, default=None, help="shorten every run to this, s")
p.add_argument("--single", type=int, default=100, help="runs timed one after another")
args = p.parse_args()
cores = os.cpu_count() or 1
fixed = {} if args.duration is None else {"duration_s": args.duration}

_, runs = pyfoc._native._sweep_plan("default", fixed, args.single, 1)
t, c = time.perf_counter(), time.process_time()
for index, _, _, toml in runs:
    pyfoc._native._sweep_run(index, toml)
single = args.single / (time.perf_counter() - t)
single_cpu = (time.process_time() - c) / args.single
print(f"one core: {single:.2f} runs/s ({1 / single:.3f} s a run, {single_cpu:.4f} s of CPU)")

n = 500 * cores
t = time.perf_counter()
before = resource.getrusage(resource.RUSAGE_CHILDREN)
df = pyfoc.sweep("default", fixed, n=n, seed=2)
rate = n / (time.perf_counter() - t)
after = resource.getrusage(resource.RUSAGE_CHILDREN)
workers_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
print(f"sweep, default executor, {n} runs: {rate:.2f} runs/s = "
      f"{rate / (cores * single):.2f} x ({cores} cores x one core); the workers' CPU time "
      f"{workers_cpu:.2f} s against {n * single_cpu:.2f} s for the runs alone "
      f"({n * single_cpu / workers_cpu:.2f})")

t = time.perf_counter()
with cf.ProcessPoolExecutor(1) as one:
    pyfoc.sweep("default", fixed, n=200, seed=2, executor=one)
rate1 = 200 / (time.perf_counter() - t)
print(f"sweep, a pool of 1 process, 200 runs: {rate1:.2f} runs/s = {rate1 / single:.2f} x one core "
      f"(the pool's own cost, whatever the load)")

base = tomllib.loads(runs[0][3])
m, sens = base["motor"], base["sensors"]
vary = {
    **fixed,
    "observer.rs_ohm": ("uniform", 0.7 * m["rs_ohm"], 1.3 * m["rs_ohm"]),
    "observer.ld_h": ("uniform", 0.8 * m["ld_h"], 1.2 * m["ld_h"]),
    "observer.lq_h": ("uniform", 0.8 * m["lq_h"], 1.2 * m["lq_h"]),
    "observer.psi_f_wb": ("uniform", 0.9 * m["psi_f_wb"], 1.1 * m["psi_f_wb"]),
    "inverter.dead_time_s": ("uniform", 0.0, 2e-6),
    "sensors.current_noise_std_a": ("uniform", 0.5 * sens["current_noise_std_a"],
                                    3.0 * sens["current_noise_std_a"]),
}
t = time.perf_counter()
df = pyfoc.sweep("default", vary, n=args.runs, seed=3)
wall = time.perf_counter() - t
import polars as pl  # noqa: E402

lost = df.filter(
    (pl.col("drive.closed_loop_exits") > 0) | pl.col("drive.fault").is_not_null()
    | (pl.col("end") != "completed") | pl.col("error").is_not_null()
)
print(f"load average: {os.getloadavg()[0]:.1f} on {cores} cores")
print(f"lock-loss sweep: {args.runs} runs on {cores} cores in {wall:.1f} s; "
      f"lost the lock: {lost.height} ({100 * lost.height / df.height:.1f} %); "
      f"errors: {df['error'].is_not_null().sum()}")

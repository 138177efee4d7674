"""``pyfoc.replay_many``: the observer over many drive logs in parallel, one DataFrame row per
log (fleet analysis).

Each log is read by ``pyfoc.read_log`` (the replay CSV or a pmsm-sim MCAP log) and filtered by
``pyfoc.Ekf.run`` with the log's own per-row periods (``dt``), both with the GIL released; the
worker sends back only the row. Rows come back in the order of ``paths``, whatever the
executor.
"""
from __future__ import annotations

import concurrent.futures as cf
import math
import os
from typing import Any, Sequence

import numpy as np

from . import pyfoc as _native  # type: ignore[attr-defined]  # the native module (no stub of its own)
from ._sweep import _chunks, _column, default_executor

# The row's columns after `path`, in order (docs/sweeps.md, "Fleet analysis").
COLUMNS = [
    "rows", "duration_s", "ts_s", "rejected_rows", "tracking_pct", "first_tracking_s",
    "nis_mean", "psi_f_end_wb", "rs_end_ohm", "speed_end_rpm",
    "angle_error_rms_deg", "angle_error_mean_deg", "angle_error_max_deg", "speed_error_rms_rad_s",
]


def _motor_args(motor: Any) -> dict[str, Any]:
    """A pyfoc.Motor, or a dict of its arguments, as the arguments (picklable)."""
    if isinstance(motor, dict):
        args = dict(motor)
    elif isinstance(motor, _native.Motor):
        args = dict(rs=motor.rs, psi_f=motor.psi_f, pole_pairs=motor.pole_pairs)
        if motor.kind == "surface":
            args["ls"] = motor.ls
        else:
            args.update(ls=None, ld=motor.ld, lq=motor.lq)
    else:
        raise TypeError(f"motor: expected a pyfoc.Motor or a dict of its arguments, "
                        f"got {type(motor).__name__}")
    _native.Motor(**args)  # refused here, once, rather than in every worker
    return args


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % (2 * np.pi) - np.pi


def replay_one(path: str, motor: dict[str, Any], scaling: str = "amplitude") -> dict[str, Any]:
    """One log's row (without ``path`` and ``error``): see COLUMNS and docs/sweeps.md."""
    log = _native.read_log(path, scaling=scaling)
    n = len(log["t"])
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row["rows"] = n
    if n == 0:
        return row
    dt = log["dt"]
    ts = float(np.median(dt))
    ekf = _native.Ekf(_native.Motor(**motor), ts)
    out = ekf.run(log["u_ab"], log["i_ab"], u_prev=log["u_prev"], dt=dt)
    status = out["status"]
    tracking = status == int(_native.Status.TRACKING)
    row["duration_s"] = float(log["t"][-1] - log["t"][0] + dt[0])
    row["ts_s"] = ts
    row["rejected_rows"] = int(np.sum(status == int(_native.Status.REJECTED)))
    row["tracking_pct"] = 100.0 * float(np.mean(tracking))
    if tracking.any():
        row["first_tracking_s"] = float(log["t"][np.argmax(tracking)] - log["t"][0])
        nis = out["nis"][tracking]
        nis = nis[np.isfinite(nis)]
        row["nis_mean"] = float(np.mean(nis)) if nis.size else None
    row["psi_f_end_wb"] = float(out["psi_f"][-1])
    row["rs_end_ohm"] = float(out["rs"][-1])
    row["speed_end_rpm"] = float(out["omega_mech"][-1] * 60.0 / (2.0 * math.pi))
    if "theta_ref" in log and tracking.any():
        err = np.degrees(_wrap(out["theta"] - log["theta_ref"]))[tracking]
        row["angle_error_rms_deg"] = float(np.sqrt(np.mean(err ** 2)))
        row["angle_error_mean_deg"] = float(np.mean(err))
        row["angle_error_max_deg"] = float(np.max(np.abs(err)))
    if "omega_ref" in log and tracking.any():
        e = (out["omega"] - log["omega_ref"])[tracking]
        row["speed_error_rms_rad_s"] = float(np.sqrt(np.mean(e ** 2)))
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in row.items()}


def _replay_chunk(chunk: Sequence[tuple[int, str]], motor: dict[str, Any],
                  scaling: str) -> list[tuple[int, dict[str, Any] | None, str | None]]:
    out: list[tuple[int, dict[str, Any] | None, str | None]] = []
    for k, path in chunk:
        try:
            out.append((k, replay_one(path, motor, scaling), None))
        except Exception as e:  # noqa: BLE001 - a log that cannot be replayed is a row
            out.append((k, None, f"{type(e).__name__}: {e}"))
    return out


def replay_many(
    paths: Sequence[str | os.PathLike[str]],
    motor: Any,
    executor: cf.Executor | None = None,
    *,
    scaling: str = "amplitude",
    chunk_size: int = 1,
) -> Any:
    """Replays every log in ``paths`` through the default EKF of ``motor``; a polars DataFrame,
    a row per log (docs/sweeps.md)."""
    import polars as pl

    if isinstance(paths, (str, os.PathLike)):
        raise TypeError("paths: expected a list of paths, got one path")
    files = [os.fspath(p) for p in paths]
    args = _motor_args(motor)
    if scaling not in ("amplitude", "power"):
        raise ValueError(f"scaling must be 'amplitude' or 'power', got {scaling!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise _native.ConfigError(f"chunk_size must be a whole number >= 1, got {chunk_size!r}")
    results: dict[int, tuple[dict[str, Any] | None, str | None]] = {}
    pool: cf.Executor = default_executor() if executor is None else executor
    try:
        work = list(enumerate(files))
        futures = {pool.submit(_replay_chunk, c, args, scaling): c for c in _chunks(work, chunk_size)}
        for fut in cf.as_completed(futures):
            try:
                done = fut.result()
            except Exception as e:  # noqa: BLE001 - a lost task is rows with its error
                done = [(k, None, f"{type(e).__name__}: {e}") for k, _ in futures[fut]]
            for k, row, error in done:
                results[k] = (row, error)
    finally:
        if executor is None:
            pool.shutdown(wait=True, cancel_futures=True)
    rows = [results.get(k, (None, "not run")) for k in range(len(files))]
    series = [pl.Series("path", files, dtype=pl.Utf8)]
    for name in COLUMNS:
        series.append(_column(name, [None if r is None else r[name] for r, _ in rows]))
    series.append(pl.Series("error", [e for _, e in rows], dtype=pl.Utf8))
    return pl.DataFrame(series)

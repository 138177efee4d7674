"""``pyfoc.sweep``: many simulator runs of one scenario with keys varied, on any
``concurrent.futures.Executor``, as one polars DataFrame.

The plan (which runs, with which values and noise seeds) is expanded by the native module from
the sweep's seed alone, before anything runs; the executor only decides where each run
executes. Results are put back in plan order, so the table is the same whatever the executor,
its number of workers or the order runs finish in.
"""
from __future__ import annotations

import concurrent.futures as cf
import os
from typing import Any, Iterable, Sequence

from . import pyfoc as _native  # type: ignore[attr-defined]  # the native module (no stub of its own)

DISTRIBUTIONS = ("uniform", "normal", "relative")


def _spelling(path: str, spec: Any) -> Any:
    """One entry of ``vary`` as the native plan reads it: a tuple must be a distribution."""
    if isinstance(spec, tuple):
        if not spec or spec[0] not in DISTRIBUTIONS:
            raise _native.ConfigError(
                f"vary.{path}: a tuple is a distribution, ('uniform', lo, hi), "
                f"('normal', mean, sd) or ('relative', sd); got {spec!r} (a list is a grid)"
            )
        return list(spec)
    return spec


def _run_chunk(chunk: Sequence[tuple[int, str]]) -> list[tuple[int, list, str | None]]:
    """Runs ``(index, scenario TOML)`` pairs in this worker: ``(index, metrics, error)`` each.
    A module-level function, so that process pools and clusters can pickle it by name."""
    out = []
    for index, toml in chunk:
        try:
            metrics, error = _native._sweep_run(index, toml)
        except Exception as e:  # noqa: BLE001 - a run that raises is a row with its error
            metrics, error = [], f"{type(e).__name__}: {e}"
        out.append((index, metrics, error))
    return out


def default_executor() -> cf.Executor:
    """A process pool over the machine's cores, with Python's default start method (fork on
    Linux before Python 3.14; where it is spawn or forkserver, a script must start the sweep
    under ``if __name__ == "__main__":``, as for any process pool)."""
    return cf.ProcessPoolExecutor(max_workers=os.cpu_count() or 1)


def _chunks(items: list, size: int) -> Iterable[list]:
    for k in range(0, len(items), size):
        yield items[k:k + size]


def _dtype(values: list):
    """A column's polars type from its non-null values (the rule of pmsm-sim's sweep table)."""
    import polars as pl

    kinds = {type(v) for v in values if v is not None}
    if not kinds:
        return pl.Float64
    if kinds == {bool}:
        return pl.Boolean
    if kinds == {int}:
        return pl.Int64
    if kinds <= {int, float}:
        return pl.Float64
    return pl.Utf8


def _text(v: Any) -> str | None:
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


def _column(name: str, values: list):
    import polars as pl

    dtype = _dtype(values)
    if dtype == pl.Utf8:
        values = [_text(v) for v in values]
    elif dtype == pl.Float64:
        values = [None if v is None else float(v) for v in values]
    return pl.Series(name, values, dtype=dtype)


def sweep(
    scenario: Any,
    vary: dict[str, Any],
    n: int = 1,
    seed: int = 0,
    executor: cf.Executor | None = None,
    *,
    chunk_size: int | None = None,
):
    """Runs ``scenario`` (a preset name, a TOML path or a dict) with the keys of ``vary``
    varied; returns a ``polars.DataFrame``, one row per run (docs/sweeps.md)."""
    import polars as pl

    if not isinstance(vary, dict):
        raise TypeError(f"vary: expected a dict of dotted paths, got {type(vary).__name__}")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise _native.ConfigError(f"n must be a whole number >= 1, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**64:
        raise _native.ConfigError(f"seed must be a whole number in [0, 2^64), got {seed!r}")
    spellings = {path: _spelling(path, spec) for path, spec in vary.items()}
    paths, runs = _native._sweep_plan(scenario, spellings, n, seed)
    if "seed" in paths:
        # A varied `seed` is the run's noise seed: one column, `seed`.
        k = paths.index("seed")
        paths = paths[:k] + paths[k + 1:]
        runs = [(i, v[:k] + v[k + 1:], s, t) for i, v, s, t in runs]
    if chunk_size is None:
        # About 64 pieces of work: enough to balance the workers, few enough that a cluster's
        # per-task overhead stays small beside the runs.
        chunk_size = max(1, min(32, len(runs) // 64))
    elif isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise _native.ConfigError(f"chunk_size must be a whole number >= 1, got {chunk_size!r}")
    work = [(index, toml) for index, _, _, toml in runs]
    own = executor is None
    pool: cf.Executor = default_executor() if executor is None else executor
    results: dict[int, tuple[list, str | None]] = {}
    try:
        futures = {pool.submit(_run_chunk, c): c for c in _chunks(work, chunk_size)}
        for fut in cf.as_completed(futures):
            try:
                done = fut.result()
            except BaseException as e:  # noqa: BLE001 - a lost worker is rows with its error
                if isinstance(e, KeyboardInterrupt):
                    raise
                done = [(i, [], f"{type(e).__name__}: {e}") for i, _ in futures[fut]]
            for index, metrics, error in done:
                results[index] = (metrics, error)
    finally:
        if own:
            pool.shutdown(wait=True, cancel_futures=True)
    return _table(paths, runs, results, pl)


def _table(paths: list[str], runs: list, results: dict[int, tuple[list, str | None]], pl: Any) -> Any:
    """The DataFrame: index, varied paths, seed, metrics in order of first appearance, error."""
    cols: dict[str, list] = {"index": [], **{p: [] for p in paths}, "seed": []}
    metric_names: list[str] = []
    known: set[str] = set()
    per_run = []
    for index, values, seed, _ in runs:
        cols["index"].append(index)
        for p, v in zip(paths, values):
            cols[p].append(v)
        cols["seed"].append(seed)
        metrics, error = results.get(index, ([], "not run"))
        m = dict(metrics)
        for name, _ in metrics:
            if name not in known:
                known.add(name)
                metric_names.append(name)
        per_run.append((m, error))
    series = [pl.Series("index", cols["index"], dtype=pl.Int64)]
    series += [_column(p, cols[p]) for p in paths]
    series.append(pl.Series("seed", cols["seed"], dtype=pl.Int64))
    series += [_column(name, [m.get(name) for m, _ in per_run]) for name in metric_names]
    series.append(pl.Series("error", [e for _, e in per_run], dtype=pl.Utf8))
    return pl.DataFrame(series)

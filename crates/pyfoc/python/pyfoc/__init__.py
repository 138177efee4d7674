"""Sensorless PMSM EKF observer (ekf-core) and drive simulator (pmsm-sim) on numpy arrays.

The native module (``pyfoc.pyfoc``, built from Rust) holds the observers, the simulator and the
log readers; this package re-exports it and adds the parallel layers written in Python:
``sweep`` (many simulator runs on any ``concurrent.futures.Executor``) and ``replay_many``
(the observer over many logs, in parallel the same way).
"""
from . import pyfoc as _native  # type: ignore[attr-defined]  # the native module
from .pyfoc import *  # noqa: F403 - the native module is the package's API
from ._fleet import replay_many
from ._frames import to_frame
from ._sweep import sweep

__doc__ = _native.__doc__

__all__ = [
    "Motor",
    "Ekf",
    "simulate",
    "sweep",
    "identify",
    "tune_qr",
    "tune_qr_mcap",
    "suite",
    "clear_buffer_pool",
    "read_log",
    "flux_check",
    "speed_bands",
    "replay_many",
    "to_frame",
    "FluxObserver",
    "DriveObserver",
    "LogError",
    "SimulationError",
    "PyfocError",
    "ConfigError",
    "FilterError",
    "Status",
    "__version__",
]

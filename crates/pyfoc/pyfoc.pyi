"""Sensorless PMSM EKF observer (ekf-core) on numpy arrays.

Timing: row k of ``u_ab`` is the voltage held over [t_k, t_k+1), row k of ``i_ab`` the currents
sampled at t_k; row k of the output is the estimate at t_k, predicted with ``u_ab[k-1]`` and
corrected with ``i_ab[k]``. SI units; angles and speeds electrical unless named ``_mech``.
"""
import os
from typing import Any, Literal, TypedDict

import numpy as np
import numpy.typing as npt

__version__: str

STATUS_TRACKING: int
"""Row status: the angle's standard deviation is below its limit."""
STATUS_UNCERTAIN: int
"""Row status: the angle is not trustworthy yet (not converged, or near standstill)."""
STATUS_REJECTED: int
"""Row status: non-finite voltage or current; the filter state was kept."""

class PyfocError(ValueError):
    """Base class of pyfoc's errors."""

class ConfigError(PyfocError):
    """Invalid motor or filter parameters; the message gives the reason."""

class FilterError(PyfocError):
    """A filter operation was refused; the filter is unchanged."""

class SimulationError(PyfocError):
    """The simulator could not run the scenario."""

class Motor:
    """Motor parameters: Rs (ohm), Ls (H), psi_f (Wb), pole pairs; ld/lq default to ls."""

    rs: float
    ls: float
    psi_f: float
    pole_pairs: int
    ld: float
    lq: float
    def __init__(
        self, rs: float, ls: float, psi_f: float, pole_pairs: int, *, ld: float | None = None, lq: float | None = None
    ) -> None: ...

class RunOutput(TypedDict):
    theta: npt.NDArray[np.float64]
    omega: npt.NDArray[np.float64]
    omega_mech: npt.NDArray[np.float64]
    i_alpha: npt.NDArray[np.float64]
    i_beta: npt.NDArray[np.float64]
    nis: npt.NDArray[np.float64]
    status: npt.NDArray[np.int8]

class StepOutput(TypedDict):
    theta: float
    omega: float
    omega_mech: float
    i_alpha: float
    i_beta: float
    nis: float
    status: Literal["tracking", "uncertain", "rejected"]

class Ekf:
    """EKF observer of a surface PMSM, states [i_alpha, i_beta, omega_e, theta].

    q (4x4 or diagonal), r (2x2 or diagonal), x0 (4), p0 (4x4 or diagonal) default to the
    motor- and ts-scaled defaults of ekf-core; x0/p0 describe the estimate one period before
    the first sample.
    """

    state: npt.NDArray[np.float64]
    """[i_alpha, i_beta, omega_e, theta], shape (4,)."""
    covariance: npt.NDArray[np.float64]
    """State covariance, shape (4, 4)."""
    u_last: npt.NDArray[np.float64]
    """Voltage that predicts the first row of the next run()."""
    ts: float
    dtype: Literal["float64", "float32"]
    def __init__(
        self,
        motor: Motor,
        ts: float,
        *,
        q: npt.ArrayLike | None = None,
        r: npt.ArrayLike | None = None,
        x0: npt.ArrayLike | None = None,
        p0: npt.ArrayLike | None = None,
        discretization: Literal["lag_free", "forward_euler"] = "lag_free",
        dtype: Literal["float64", "float32"] = "float64",
        covariance_update: Literal["joseph", "standard"] = "joseph",
    ) -> None: ...
    def run(self, u_ab: npt.ArrayLike, i_ab: npt.ArrayLike, *, u_prev: npt.ArrayLike | None = None) -> RunOutput:
        """Filter a record of shape (N, 2) each; continues from the current state. Releases the GIL."""
    def step(self, u_prev: npt.ArrayLike, i: npt.ArrayLike) -> StepOutput:
        """One sample: predict with u_prev, correct with i."""
    def reset(self, x: npt.ArrayLike, p: npt.ArrayLike) -> None:
        """Replace state and covariance; FilterError if not finite."""

def simulate(
    scenario: str | os.PathLike[str] | dict[str, Any] | None = None,
    *,
    duration: float | None = None,
    seed: int | None = None,
) -> dict[str, Any]:
    """Run the drive simulator (pmsm-sim) on a preset name, a TOML path or a dict with the TOML
    layout (None: the "default" preset). Returns arrays aligned on the PWM period: ``t``,
    true ``theta``/``omega``/``speed_rpm``/``torque``/``load_torque``/``i_ab``/``i_dq``,
    measured ``i_ab_meas``, applied ``u_ab``, ``duties`` (N, 3), ``speed_ref_rpm``, the
    desktop EKF's ``theta_est``/``omega_est``/``angle_error_deg``/``nis``/``p_diag`` (N, 4),
    the controller's own observer (``controller_theta_est``/``controller_omega_est``, foc
    scenarios) and the seed filter (``seed_theta_est``, when it runs); plus ``metrics`` (dict,
    as ``pmsm-sim --json``), ``completed`` and ``scenario``. Releases the GIL."""

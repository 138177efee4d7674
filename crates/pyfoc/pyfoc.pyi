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

    q (4x4 or diagonal), r (2x2 or diagonal), x0 (shape (4,)), p0 (4x4 or diagonal) default to
    the motor- and ts-scaled defaults of ekf-core; x0/p0 describe the estimate one period
    before the first sample.

    Inputs: any real numeric array-like (float, int, unsigned; any strides, read-only and
    broadcast views included); complex, bool, object, string and other dtypes raise TypeError,
    wrong shapes ValueError (naming the argument), records too large for the machine's memory
    MemoryError (before anything is allocated). Non-finite samples are rejected rows.

    Threads: every method takes the filter's lock with the GIL released, so calls on one Ekf
    from several threads are serialized (each completes, in some order; the state then
    continues from whichever ran last) and other Python threads keep running meanwhile.
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
        """Filter a record of shape (N, 2) each; continues from the current state (row 0 predicts
        with u_prev if given, else u_last). Releases the GIL."""
    def step(self, u_prev: npt.ArrayLike, i: npt.ArrayLike) -> StepOutput:
        """One sample: predict with u_prev, correct with i."""
    def reset(self, x: npt.ArrayLike, p: npt.ArrayLike) -> None:
        """Replace state and covariance; FilterError if not finite."""

def simulate(
    scenario: str | os.PathLike[str] | dict[str, Any] | None = None,
    *,
    duration: float | None = None,
    seed: int | None = None,
    mcap: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """Run the drive simulator (pmsm-sim) on a preset name, a TOML path or a dict with the TOML
    layout (None: the "default" preset). Returns arrays aligned on the PWM period: ``t``,
    true ``theta``/``omega``/``speed_rpm``/``torque``/``load_torque``/``i_ab``/``i_dq``,
    measured ``i_ab_meas``, applied ``u_ab``, ``duties`` (N, 3), ``speed_ref_rpm``, the
    desktop EKF's ``theta_est``/``omega_est``/``angle_error_deg``/``nis``/``p_diag`` (N, 4),
    the controller's own observer (``controller_theta_est``/``controller_omega_est``, foc
    scenarios) and the seed filter (``seed_theta_est``, when it runs); plus ``metrics`` (dict,
    as ``pmsm-sim --json``), ``completed`` and ``scenario``. With ``mcap``, the run is also
    logged to that MCAP file (as ``pmsm-sim run`` writes it; SimulationError if it cannot be
    created). Malformed scenarios raise ConfigError; a run whose trace would not fit in
    memory raises MemoryError before it starts. Releases the GIL."""

class AngleError(TypedDict):
    rms_deg: float
    mean_deg: float
    max_abs_deg: float
    samples: int

class FilterScore(TypedDict):
    log_likelihood: float | None
    """-0.5 sum(log det S_k + NIS_k) over the scored samples (None if the filter failed)."""
    mean_nis: float | None
    angle_error: AngleError | None
    failure: str | None

class NormalizedNoise(TypedDict):
    sigma_z: list[float]
    """Sensor noise std [alpha, beta], fraction of I_c = psi_f / Ls."""
    rho_z: float
    sigma_i: float
    """Current model error per sample, fraction of I_c."""
    sigma_w: float
    """Speed random walk, rad per sample, per sample (w_e Ts units)."""
    sigma_th: float
    """Angle random walk, rad per sample."""

class TuneReport(TypedDict):
    q: npt.NDArray[np.float64]
    """Proposed Q, (4, 4), SI (A^2, A^2, (rad/s)^2, rad^2): pass to Ekf(q=...)."""
    r: npt.NDArray[np.float64]
    """Proposed R, (2, 2), A^2: pass to Ekf(r=...)."""
    tuned: NormalizedNoise
    start: NormalizedNoise
    r_shape: Literal["full", "isotropic"]
    before: FilterScore
    """The default (start) filter on the record."""
    after: FilterScore
    """The tuned filter on the record."""
    mean_nis_before: float
    mean_nis_after: float
    evaluations: int
    converged: bool
    at_bound: list[str]
    """Parameters that ended on the search box (the data do not pin them)."""
    skip: int
    samples_scored: int
    samples_rejected: int
    characteristic_current_a: float
    ts_s: float
    toml: str
    """The proposal as a TOML table (scenario files cannot set the observer's noise)."""

class McapTuneReport(TuneReport):
    scenario: str
    periods: int
    sensor_r: npt.NDArray[np.float64]
    """The R the scenario's current sensor produces (two-phase sensing), (2, 2), A^2."""
    replay_matches_log: bool
    """The default filter replayed on the log reproduces the logged observer's angle."""
    replay_max_diff_rad: float
    min_speed_rad_s: float

def tune_qr(
    motor: Motor,
    ts: float,
    u_ab: npt.ArrayLike,
    i_ab: npt.ArrayLike,
    *,
    theta_true: npt.ArrayLike | None = None,
    omega_true: npt.ArrayLike | None = None,
    skip: int | None = None,
    r_shape: Literal["full", "isotropic"] = "full",
    max_evals: int = 5000,
    x0: npt.ArrayLike | None = None,
    discretization: Literal["lag_free", "forward_euler"] = "lag_free",
    min_speed: float | None = None,
    bound_decades: float = 3.0,
) -> TuneReport:
    """Propose Q and R for Ekf from a record by maximizing the innovation log-likelihood
    L = -0.5 sum_k (log det S_k + NIS_k) over the samples after ``skip`` (default
    min(N/5, 0.1 s / ts)), with Nelder-Mead on the logs of the normalized noise levels
    (ekf_core::noise units), each within ``bound_decades`` decades of the default.
    ``u_ab``/``i_ab`` (N, 2) as for Ekf.run; ``theta_true`` (and ``omega_true``, for the
    window |omega| >= ``min_speed``) add the angle error before/after. ``r_shape="full"``
    fits alpha and beta sigmas and their correlation (what phase-current sensing gives),
    "isotropic" one sigma. Each evaluation is one filter pass over the record.
    ValueError for shapes/too short records, ConfigError for bad parameters or options.
    Releases the GIL."""

def tune_qr_mcap(
    path: str | os.PathLike[str],
    *,
    skip: int | None = None,
    r_shape: Literal["full", "isotropic"] = "full",
    max_evals: int = 5000,
    x0: npt.ArrayLike | None = None,
    discretization: Literal["lag_free", "forward_euler"] = "lag_free",
    min_speed: float | None = None,
    bound_decades: float = 3.0,
) -> McapTuneReport:
    """tune_qr on a pmsm-sim MCAP log (protobuf or JSON period channel): motor and Ts from
    its scenario, the voltage the simulator's observer was given, the true angle and speed;
    the angle-error window defaults to |omega| >= 5 % of rated speed. PyfocError naming the
    file when it cannot be read. Releases the GIL."""

def suite(*, short: bool = False, seed: int = 1, ideal: bool = False) -> dict[str, Any]:
    """The observer suite of `pmsm-sim suite`: the three reference motors at 10/50/100 %
    rated speed, a rated load step and starts from unknown angles; the seed's filter, the
    flux + PLL baseline and the default EKF side by side. Returns the report as a dict
    (`motors`, `steady`, `transients`, `checks`, ...) plus `markdown` (the printed tables) and
    `all_pass`. SimulationError if a run fails. Releases the GIL."""

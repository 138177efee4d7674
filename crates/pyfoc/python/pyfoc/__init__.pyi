"""Sensorless PMSM EKF observer (ekf-core) on numpy arrays.

Timing: row k of ``u_ab`` is the voltage held over [t_k, t_k+1), row k of ``i_ab`` the currents
sampled at t_k; row k of the output is the estimate at t_k, predicted with ``u_ab[k-1]`` and
corrected with ``i_ab[k]``. SI units; angles and speeds electrical unless named ``_mech``.
"""
import concurrent.futures
import enum
import os
from typing import Any, Literal, Mapping, Sequence, TypedDict, final

import numpy as np
import numpy.typing as npt
import polars

# The TypedDicts below (RunOutput, StepOutput, TuneReport, ...) describe the returned dicts for
# type checkers only; they do not exist at runtime (crates/pyfoc/stubtest-allowlist.txt).

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

__version__: str

class Status(enum.IntEnum):
    """Status of an estimate: the value of each row of ``Ekf.run(...)["status"]`` (int8) and
    the ``status`` of ``Ekf.step``."""

    TRACKING = 0
    """The angle can be trusted: its standard deviation is below its limit, the innovations are
    consistent with the noise seen before, and the speed is known to be away from zero."""
    UNCERTAIN = 1
    """The filter ran but the angle is not trustworthy: not converged, near standstill, or the
    innovations far out of line (the model no longer explains the currents: a lost filter)."""
    REJECTED = 2
    """The step was refused and the state kept: a voltage or current that is not finite (NaN,
    +-inf); a finite one beyond anything a drive applies or a motor carries (a voltage moving
    the flux by more than 20 psi_f in one period, a current above 100 psi_f / L: a corrupted
    sample) or so large that the step's arithmetic overflows; a singular innovation
    covariance; with ``dt``, a period not in (0, 64 ts]. Other finite samples are filtered,
    however unusual (they show as large innovations, NIS, and
    UNCERTAIN). A refused row is data, not an error: one corrupt sample costs its row, not
    the call."""

class PyfocError(ValueError):
    """Base class of pyfoc's errors."""

class ConfigError(PyfocError):
    """Invalid motor or filter parameters; the message gives the reason."""

class FilterError(PyfocError):
    """A filter operation was refused; the filter is unchanged."""

class SimulationError(PyfocError):
    """The simulator could not run the scenario."""

class LogError(PyfocError):
    """A drive log or motor file could not be read. The message names the file and, for a
    malformed CSV, the line and column; also as attributes (None where they do not apply)."""

    file: str | None
    line: int | None
    column: int | None

@final
class Motor:
    """Motor parameters: Rs (ohm), Ls (H), psi_f (Wb), pole pairs; ld/lq default to ls.
    For an interior PMSM give ld and lq (ls may then be None and reads back as their mean).
    Immutable."""

    @property
    def rs(self) -> float: ...
    @property
    def ls(self) -> float: ...
    @property
    def psi_f(self) -> float: ...
    @property
    def pole_pairs(self) -> int: ...
    @property
    def ld(self) -> float: ...
    @property
    def lq(self) -> float: ...
    @property
    def kind(self) -> Literal["surface", "interior", "inverse_salient"]:
        """Saliency: "inverse_salient" (lq < ld) is accepted; check ld and lq are not swapped."""
    def __new__(
        cls,
        rs: float,
        ls: float | None,
        psi_f: float,
        pole_pairs: int,
        *,
        ld: float | None = None,
        lq: float | None = None,
    ) -> Motor: ...
    @staticmethod
    def from_datasheet(
        *,
        pole_pairs: int,
        r_ll: float,
        l_ll: float | None = None,
        kv_rpm_per_v: float | None = None,
        kt_nm_per_a: float | None = None,
        ld_ll: float | None = None,
        lq_ll: float | None = None,
    ) -> Motor:
        """Motor from line-to-line R and L (halved to per phase) and Kv (rpm per volt of
        line-to-line peak back-EMF) or Kt (N m per peak phase ampere): exactly one of them."""
    @staticmethod
    def from_flux_map(
        rs: float,
        pole_pairs: int,
        i_d: npt.ArrayLike,
        i_q: npt.ArrayLike,
        psi_d: npt.ArrayLike,
        psi_q: npt.ArrayLike,
    ) -> Motor:
        """A saturating motor from its flux maps: i_d (n_d,) and i_q (n_q,) ascending, A;
        psi_d, psi_q (n_d, n_q), Wb, psi[a, b] at (i_d[a], i_q[b]), magnet flux in psi_d; at
        most 32 points per axis. ConfigError naming the problem for wrong shapes, non-finite
        values, unordered axes, non-monotonic fluxes or a singular inductance. ld, lq, psi_f
        read back the small-signal values at zero current. Ekf runs on the map (tracking
        'default' and 'off' take the map as given; 'flux' learns the map's psi_d offset
        online, ekf-core's FluxOffsetTracking, for magnets warmer or colder than when the map
        was measured, and reports psi_f as the map's psi_d(0, 0) plus it), FluxObserver on
        the map's active flux; Drive and tune use the small-signal constants."""
    @property
    def has_flux_map(self) -> bool:
        """Whether the motor is given by a flux map (from_flux_map)."""

class RunOutput(TypedDict):
    theta: npt.NDArray[np.float64]
    omega: npt.NDArray[np.float64]
    omega_mech: npt.NDArray[np.float64]
    i_alpha: npt.NDArray[np.float64]
    i_beta: npt.NDArray[np.float64]
    nis: npt.NDArray[np.float64]
    psi_f: npt.NDArray[np.float64]
    """Tracked flux linkage, Wb (the configured one with tracking="off")."""
    rs: npt.NDArray[np.float64]
    """Stator resistance in use, ohm (tracked with tracking="default")."""
    winding_temperature: npt.NDArray[np.float64]
    """Winding temperature derived from rs, deg C (20 at the configured rs)."""
    status: npt.NDArray[np.int8]
    """The values of Status."""

class StepOutput(TypedDict):
    theta: float
    omega: float
    omega_mech: float
    i_alpha: float
    i_beta: float
    nis: float
    psi_f: float
    """Tracked flux linkage, Wb (the configured one with tracking="off")."""
    rs: float
    """Stator resistance in use, ohm (tracked with tracking="default")."""
    winding_temperature: float
    """Winding temperature derived from rs, deg C (20 at the configured rs)."""
    status: Status

@final
class Ekf:
    """EKF observer of a PMSM (surface, or interior with the active-flux model when
    ld != lq), states [i_alpha, i_beta, omega_e, theta].

    q (4x4 or diagonal), r (2x2 or diagonal), x0 (shape (4,)), p0 (4x4 or diagonal) default to
    the motor- and ts-scaled defaults of ekf-core; x0/p0 describe the estimate one period
    before the first sample. tracking: "default" tracks the flux linkage online and the
    resistance by the split filter with the thermal link (ekf-core's ObserverConfig::new),
    "flux" the flux only (rs fixed), "off" uses the motor's parameters as given.
    voltage_delay_s: the delay of the voltage the inverter applied behind the u_ab given for
    the period, s; negative when the applied voltage leads it (a firmware that turns its
    command ahead by the speed times the time to the PWM update). The prediction turns each
    u_ab row by -omega * voltage_delay_s. Within [-2 ts, 2 ts] (ConfigError otherwise); 0 uses
    u_ab as given.
    inverter_voltage_v: the inverter's voltage error (dead time), V, as foc's self-commissioning
    reports it (the voltage lost along a current aligned with a phase axis); subtracted along
    the signs of the estimated phase currents. Within [0, 100] (ConfigError otherwise); 0: none.
    acceleration_feedforward: True: the speed prediction follows the q current through the
    rotor's acceleration per ampere, learnt online from the filter's own speed changes
    (ekf-core's AccelerationFeedforward with its defaults; it acts on drives with current or
    duty steps and stays off where the q current only follows the speed); False: the speed
    is a random walk (ekf-core's ObserverConfig::new, the filter foc and the simulator run).
    None (the default): True for a constant-parameter motor, False on a flux map. Not
    available on a flux map (ConfigError).
    saturating: True for a saturating interior motor (a PM-assisted synchronous reluctance
    motor, or an interior PM motor whose Lq falls well below its small-signal value at rated
    current) told the small-signal constants a low-current commissioning measures: the model's
    Lq is the midpoint of the told ld and lq (ekf-core's ObserverConfig::saturating); a surface
    motor is unchanged. The price on a motor that does not saturate: an angle bias of about
    (lq - ld) i_q / (2 psi_a) at steady state. Not available on a flux map (ConfigError): there
    the map is the model.
    input_calibration: True for a recorded drive whose voltage timing, dead time or resistance
    is not known: a drive observer (pyfoc.DriveObserver) runs on the same rows, and every 20 ms,
    once 50 of its rows have adapted, its averages (calibration()'s weighting, the lead held
    to [0, 2 ts], the dead-time voltage >= 0) are handed to this filter as voltage_delay_s,
    inverter_voltage_v and, when it differs by more than 5 %, the tracked rs. The rows before
    the first hand-over run on the told values; nothing is handed over while the tracked flux
    is more than 3 % off the told one (the drive observer assumes the told flux). The first
    run() of a new filter primes it with its own rows: a copy runs over the record first, and
    the voltage delay the copy's calibration handed over last is this filter's from row 0 (the
    lead is a constant of the logging firmware, and a lead found part-way leaves the record
    with two angle offsets; the inverter voltage and rs, handed over together, are left to the
    filter's own hand-overs), as is the innovation level its status check learnt (else a short
    record reads UNCERTAIN while it is learnt). prime() does it for a record filtered in
    chunks. False: the
    told values throughout (ekf-core's ObserverConfig::new, the filter foc and the simulator
    run). None (the default): True for a constant-parameter motor told neither
    voltage_delay_s nor inverter_voltage_v, else False. Not available on a flux map
    (ConfigError). Both options with False reproduce the simulator's EKF on its own logs.
    The defaults cost about twelve times the firmware filter's time per row (1.3 against 0.11
    us on one core: the calibration runs two more filters, and the first run passes over the
    record twice).

    Inputs: any real array-like, converted to float64 by numpy (ndarrays of float, int,
    unsigned or bool dtype, with any strides, read-only and broadcast views included; nested
    sequences of numbers); None, str, and ndarrays of complex, object, string, datetime or
    structured dtype raise TypeError, wrong shapes ValueError (naming the argument), records
    too large for the machine's memory MemoryError (before anything is allocated).
    Samples the filter refuses are rejected rows (Status.REJECTED: non-finite, implausible
    or so large that the step overflows), not errors; with dt, a rejected row is a skipped
    cycle (its period joins the next row's).

    Properties are read-only; ``state``, ``covariance`` and ``u_last`` return copies.

    Threads: every method takes the filter's lock with the GIL released, so calls on one Ekf
    from several threads are serialized (each completes, in some order; the state then
    continues from whichever ran last) and other Python threads keep running meanwhile.
    """

    @property
    def state(self) -> npt.NDArray[np.float64]:
        """[i_alpha, i_beta, omega_e, theta], shape (4,)."""
    @property
    def covariance(self) -> npt.NDArray[np.float64]:
        """State covariance, shape (4, 4)."""
    @property
    def u_last(self) -> npt.NDArray[np.float64]:
        """Voltage that predicts the first row of the next run()."""
    @property
    def ts(self) -> float:
        """Sample time, s."""
    @property
    def dtype(self) -> Literal["float64", "float32"]:
        """Precision of the filter."""
    @property
    def acceleration_feedforward(self) -> bool:
        """Whether the acceleration feedforward is on (as given, or the default)."""
    @property
    def input_calibration(self) -> bool:
        """Whether the online input calibration is on (as given, or the default)."""
    def __new__(
        cls,
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
        tracking: Literal["default", "flux", "off"] = "default",
        voltage_delay_s: float = 0.0,
        inverter_voltage_v: float = 0.0,
        acceleration_feedforward: bool | None = None,
        saturating: bool = False,
        input_calibration: bool | None = None,
    ) -> Ekf: ...
    def run(
        self,
        u_ab: npt.ArrayLike,
        i_ab: npt.ArrayLike,
        *,
        u_prev: npt.ArrayLike | None = None,
        dt: npt.ArrayLike | None = None,
        out: RunOutput | None = None,
    ) -> RunOutput:
        """Filter a record of shape (N, 2) each; continues from the current state (row 0 predicts
        with u_prev if given, else u_last). Releases the GIL. ``out``: a dict of the ten output
        arrays (e.g. a previous result of the same length), written in place and returned.
        ``dt``: shape (N,), the period that ended at each row, s (finite, > 0; ValueError
        naming ``dt`` otherwise); without it every period is ``ts``. The first run of a new
        filter with the input calibration on primes it with its rows (see prime())."""
    def prime(
        self,
        u_ab: npt.ArrayLike,
        i_ab: npt.ArrayLike,
        *,
        u_prev: npt.ArrayLike | None = None,
        dt: npt.ArrayLike | None = None,
    ) -> float | None:
        """Prime the input calibration with a whole record (arguments as run takes them)
        before filtering it in chunks: a copy runs over it and the voltage delay its
        calibration handed over last (and the innovation level its status check learnt) is
        set here; where the copy ends with an Rs that matters for the record, the filter is
        first built again told that Rs (its winding temperature keeps the told Rs as its
        reference). The filter's state does not move. After
        prime(), run() or step() the next run does not prime, so prime(u, i) then run() on
        chunks gives what one run(u, i) gives. Returns the delay set (voltage_delay_s, s), or
        None when no delay was set (the calibration off or a flux map: nothing set; no
        hand-over on the record)."""
    def step(self, u_prev: npt.ArrayLike, i: npt.ArrayLike) -> StepOutput:
        """One sample: predict with u_prev, correct with i."""
    def reset(self, x: npt.ArrayLike, p: npt.ArrayLike) -> None:
        """Replace state and covariance; FilterError if not finite."""

class FluxOutput(TypedDict):
    theta: npt.NDArray[np.float64]
    omega: npt.NDArray[np.float64]
    omega_mech: npt.NDArray[np.float64]
    status: npt.NDArray[np.int8]
    """Status.UNCERTAIN on every accepted row (no confidence measure: it never claims TRACKING),
    REJECTED otherwise."""

@final
class FluxObserver:
    """The flux observer with PLL (ekf-core's baseline, usual tuning 0.1 / ts)."""

    @property
    def ts(self) -> float:
        """Sample time, s."""
    def __new__(cls, motor: Motor, ts: float) -> FluxObserver: ...
    def run(
        self,
        u_ab: npt.ArrayLike,
        i_ab: npt.ArrayLike,
        *,
        u_prev: npt.ArrayLike | None = None,
        dt: npt.ArrayLike | None = None,
    ) -> FluxOutput:
        """Run over a record (Ekf.run's timing); ``dt`` is validated, the step is the fixed ts."""

class DriveOutput(TypedDict):
    theta: npt.NDArray[np.float64]
    omega: npt.NDArray[np.float64]
    omega_mech: npt.NDArray[np.float64]
    i_alpha: npt.NDArray[np.float64]
    i_beta: npt.NDArray[np.float64]
    nis: npt.NDArray[np.float64]
    accel: npt.NDArray[np.float64]
    """Electrical acceleration, rad/s^2."""
    voltage_lead: npt.NDArray[np.float64]
    """Lead of the applied voltage over the logged one, s."""
    rs: npt.NDArray[np.float64]
    """Resistance in use (configured plus estimated error), ohm."""
    dead_time: npt.NDArray[np.float64]
    """Inverter dead-time voltage, V."""
    status: npt.NDArray[np.int8]
    """Status.TRACKING while the observer tracks, UNCERTAIN otherwise, REJECTED for a refused row."""

@final
class DriveObserver:
    """ekf-core's drive observer (DriveConfig::new(motor, ts)): an EKF for recorded drives with
    the acceleration, the voltage lead, the resistance error and the dead-time voltage as states."""

    @property
    def ts(self) -> float:
        """Sample time, s."""
    @property
    def state(self) -> npt.NDArray[np.float64]:
        """[i_alpha, i_beta, omega_e, theta, accel, voltage_lead, d_rs, dead_time], shape (8,) (a copy)."""
    @property
    def covariance(self) -> npt.NDArray[np.float64]:
        """State covariance, shape (8, 8) (a copy)."""
    def __new__(cls, motor: Motor, ts: float) -> DriveObserver: ...
    def run(
        self,
        u_ab: npt.ArrayLike,
        i_ab: npt.ArrayLike,
        *,
        u_prev: npt.ArrayLike | None = None,
        dt: npt.ArrayLike | None = None,
    ) -> DriveOutput:
        """Run over a record (Ekf.run's timing), continuing from the current state; ``dt``: the
        period that ended at each row (a period above 64 ts is a REJECTED row)."""
    def calibration(self) -> Calibration | None:
        """The record's input errors from every row run so far (the tracked rows' estimates
        weighted by the speed squared) as Ekf's arguments; None before a tracked row."""

class Calibration(TypedDict):
    voltage_delay_s: float
    """Minus the lead of the applied voltage over the logged one, s (Ekf's voltage_delay_s)."""
    rs_ohm: float
    inverter_voltage_v: float
    samples: int
    """Rows averaged."""

class DriveLog(TypedDict, total=False):
    t: npt.NDArray[np.float64]
    dt: npt.NDArray[np.float64]
    """The period that ended at each row, s."""
    u_ab: npt.NDArray[np.float64]
    """Row k: the voltage held over [t_k, t_k+1)."""
    i_ab: npt.NDArray[np.float64]
    u_prev: npt.NDArray[np.float64]
    """The voltage before row 0."""
    theta_ref: npt.NDArray[np.float64]
    omega_ref: npt.NDArray[np.float64]

def read_log(
    path: str | os.PathLike[str], *, scaling: Literal["amplitude", "power"] = "amplitude"
) -> DriveLog:
    """Read a drive log (CSV: t_s, dt_s, u_alpha_v, u_beta_v, i_alpha_a, i_beta_a, optional
    theta_ref_rad, omega_ref_rad_s; or a pmsm-sim MCAP log) in pyfoc's timing; LogError
    naming file, line and column."""

def flux_check(
    motor: Motor,
    ts: float,
    u_ab: npt.ArrayLike,
    i_ab: npt.ArrayLike,
    theta: npt.ArrayLike,
    status: npt.ArrayLike,
    *,
    dt: npt.ArrayLike | None = None,
) -> dict[str, Any] | None:
    """The record's back-EMF per unit speed against the motor's psi_f, from a run's own theta
    and status (Ekf.run's convention: row k predicts with u_ab[k-1]; dt the period that ended
    at each row, default ts): light-load, steady blocks where the status is TRACKING. A dict
    (blocks, flux_wb, told_wb, ratio, off: more than 10 % from the told flux) or None when no
    block qualifies."""

def speed_bands(
    ts: float,
    theta: npt.ArrayLike,
    theta_ref: npt.ArrayLike,
    omega_ref: npt.ArrayLike,
    psi_f: float,
    *,
    dt: npt.ArrayLike | None = None,
) -> dict[str, Any] | None:
    """A run's angle error by speed band (10-20, 20-40, 40-70, 70-100 % of the largest
    |omega_ref|) and direction, scored as pmsm-sim replay scores (|omega_ref| >= 10 % of its
    largest, 20 ms after each period longer than 1.35 ts left out, the circular mean removed,
    rows more than 45 deg off left out), and fitted as c + a / w + b w: a d-axis voltage the
    model lacks (d_voltage_v = a psi_f) and a timing (delay_s = b: the reference's delay or the
    voltage's lead). A dict (offset_deg; bands: dicts with from_share, to_share, forward,
    samples, speed_rad_s, mean_deg, rms_deg; fit: a dict with constant_deg, d_voltage_v,
    delay_s, residual_rms_deg, or None when the run turns one way only or its speeds are too
    alike), or None with fewer than 16 rows to use."""

def simulate(
    scenario: str | os.PathLike[str] | dict[str, Any] | None = None,
    *,
    duration: float | None = None,
    seed: int | None = None,
    mcap: str | os.PathLike[str] | None = None,
    log_time: Literal["wall", "zero"] = "wall",
) -> dict[str, Any]:
    """Run the drive simulator (pmsm-sim) on a preset name, a TOML path or a dict with the TOML
    layout (None: the "default" preset). Returns arrays aligned on the PWM period: ``t``,
    true ``theta``/``omega``/``speed_rpm``/``torque``/``load_torque``/``i_ab``/``i_dq``,
    measured ``i_ab_meas``, applied ``u_ab``, ``duties`` (N, 3), ``speed_ref_rpm``, the
    desktop EKF's ``theta_est``/``omega_est``/``angle_error_deg``/``nis``/``p_diag`` (N, 4),
    the controller's own observer (``controller_theta_est``/``controller_omega_est``, foc
    scenarios) and the seed filter (``seed_theta_est``, when it runs); plus ``metrics`` (dict,
    as ``pmsm-sim --json`` but NaN kept where JSON writes null), ``completed`` and
    ``scenario``. With ``mcap``, the run is also
    logged to that MCAP file (as ``pmsm-sim run`` writes it; SimulationError if it cannot be
    created), its time stamps the wall-clock start plus the simulated time (``log_time=
    "wall"``) or the simulated time alone (``"zero"``). Malformed scenarios raise ConfigError; a run whose trace would not fit in
    memory raises MemoryError before it starts. Releases the GIL."""

class AngleError(TypedDict):
    rms_deg: float
    mean_deg: float
    max_abs_deg: float
    samples: int

class FilterScore(TypedDict):
    log_likelihood: float
    """-0.5 sum(log det S_k + NIS_k) over the scored samples (-inf if the filter failed)."""
    mean_nis: float
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
    max_evals: int | None = None,
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
    max_evals: int | None = None,
    x0: npt.ArrayLike | None = None,
    discretization: Literal["lag_free", "forward_euler"] = "lag_free",
    min_speed: float | None = None,
    bound_decades: float = 3.0,
) -> McapTuneReport:
    """tune_qr on a pmsm-sim MCAP log (protobuf or JSON period channel): motor and Ts from
    its scenario, the voltage the simulator's observer was given, the true angle and speed;
    the angle-error window defaults to |omega| >= 5 % of rated speed. PyfocError naming the
    file when it cannot be read. Releases the GIL."""

def identify(
    scenario: str | os.PathLike[str] | dict[str, Any], *, seed: int | None = None
) -> dict[str, Any]:
    """Self-commissioning of the scenario's motor (pmsm-sim identify): Rs, Ld, Lq, psi_f, J and
    the inverter's voltage error from standstill and a short I/f spin, with the scenario's
    inverter and sensing. Returns the report as a dict (ok, identified, truth, errors_pct,
    steps, total_time_s, error, error_kind, failed_step, pwm_off_at_end); a failed
    identification is reported (ok False), not raised. Releases the GIL."""

def suite(*, short: bool = False, seed: int | None = None, ideal: bool = False) -> dict[str, Any]:
    """(`seed`: None means 1.) The observer suite of `pmsm-sim suite`: the three reference motors at 10/50/100 %
    rated speed, a rated load step and starts from unknown angles; the seed's filter, the
    flux + PLL baseline and the default EKF side by side. Returns the report as a dict
    (`motors`, `steady`, `transients`, `checks`, ...) plus `markdown` (the printed tables) and
    `all_pass`. SimulationError if a run fails. Releases the GIL."""

def clear_buffer_pool() -> int:
    """Drops the buffers `Ekf.run` keeps for reuse and returns the bytes they held: the output
    arrays of the last fresh result (pyfoc's reference to them; their memory is freed once
    no result or view uses it) and the spare copies of inputs. `run` hands a dropped result's
    memory to the next call of the same or a somewhat smaller length (already mapped: no page
    faults, no zeroing by the kernel); at most 256 MiB of outputs and 128 MiB of input copies
    stay held after the results are gone. Later calls fill the pool again."""

def sweep(
    scenario: str | os.PathLike[str] | dict[str, Any],
    vary: dict[str, Any],
    n: int = 1,
    seed: int = 0,
    executor: concurrent.futures.Executor | None = None,
    *,
    chunk_size: int | None = None,
) -> polars.DataFrame:
    """Run ``scenario`` (a preset name, a TOML path or a dict) many times with the dotted keys
    of ``vary`` varied: a list is a grid axis, ``("uniform", lo, hi)``, ``("normal", mean,
    sd)`` and ``("relative", sd)`` are drawn ``n`` times per grid point, a single value is a
    fixed setting. Returns a polars DataFrame, a row per run: ``index``, each varied path,
    ``seed`` (the run's noise seed), the run's metrics flattened with dotted names (no
    wall-clock figures), ``error`` (None, or why the run failed: a failed run is a row).
    Deterministic for ``seed`` whatever the executor: any concurrent.futures.Executor (default:
    a process pool over the cores; a Dask ``Client.get_executor()`` runs it on a cluster).
    ``chunk_size``: runs per submitted task (default: about 64 tasks in all, at most 32 runs
    each). Malformed plans raise ConfigError before anything runs."""

def replay_many(
    paths: Sequence[str | os.PathLike[str]],
    motor: Motor | dict[str, Any],
    executor: concurrent.futures.Executor | None = None,
    *,
    scaling: Literal["amplitude", "power"] = "amplitude",
    chunk_size: int = 1,
) -> polars.DataFrame:
    """Replay many drive logs (read_log: the replay CSV or pmsm-sim MCAP) through the default
    EKF of ``motor`` (a Motor or a dict of its arguments), each with its own per-row periods,
    in parallel on ``executor`` (as ``sweep``'s). A polars DataFrame, a row per log in the
    order of ``paths``: ``path``, ``rows``, ``duration_s``, ``ts_s`` (median period),
    ``rejected_rows``, ``tracking_pct``, ``first_tracking_s``, ``nis_mean``, ``psi_f_end_wb``,
    ``rs_end_ohm``, ``speed_end_rpm`` and, when the log has the reference angle and speed, the
    angle error (``angle_error_rms_deg``, ``_mean_deg``, ``_max_deg``) and
    ``speed_error_rms_rad_s`` over the tracking rows; ``error`` (None, or why the log could
    not be replayed: a row, never a lost batch)."""

def to_frame(result: Mapping[str, Any]) -> polars.DataFrame:
    """A result of simulate, Ekf.run, DriveObserver.run, FluxObserver.run or read_log as a
    polars DataFrame, a row per period: 1-D arrays as columns, (N, k) arrays split into named
    columns (i_ab -> i_alpha, i_beta; i_dq -> i_d, i_q; u_ab -> u_alpha, u_beta; duties ->
    duty_a, duty_b, duty_c; p_diag -> p_i_alpha, p_i_beta, p_omega, p_theta); what is not per
    row (metrics, completed, scenario, u_prev) left out."""

"""Shared fixtures: the seed reference record (servo, 2500 samples) from tests/data."""
import pathlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
SEED_CSV = ROOT / "tests" / "data" / "seed_reference.csv"
# `pyfoc.Ekf`'s options for the filter foc and the simulator run (ekf-core's
# `ObserverConfig::new`): the defaults add the acceleration feedforward and the online input
# calibration, which are for recorded drives.
FIRMWARE = dict(acceleration_feedforward=False, input_calibration=False)


def score_record(theta, theta_ref, omega_ref, dt, ts):
    """A recorded drive's angle errors scored by the replay's rules (docs/accuracy.md,
    "Recorded drives"): the samples with |omega_ref| >= 10 % of its maximum, leaving out 20 ms
    after each period longer than 1.35 ts; the constant circular-mean offset removed. Returns
    the scored samples' mask and their absolute errors in degrees (a non-finite estimate
    counts as 180 deg)."""
    scored = np.abs(omega_ref) >= 0.1 * np.abs(omega_ref).max()
    for k in np.flatnonzero(dt > 1.35 * ts):
        if k > 0:
            scored[k:k + int(round(0.02 / ts))] = False
    err = (theta - theta_ref + np.pi) % (2 * np.pi) - np.pi
    err[~np.isfinite(err)] = np.pi
    offset = np.angle(np.mean(np.exp(1j * err[scored])))
    return scored, np.degrees(np.abs((err[scored] - offset + np.pi) % (2 * np.pi) - np.pi))


@pytest.fixture(scope="session")
def seed_record():
    meta = {}
    with open(SEED_CSV) as f:
        for line in f:
            if not line.startswith("#"):
                break
            for item in line[1:].split():
                if "=" in item:
                    k, v = item.split("=", 1)
                    meta[k] = v
    with open(SEED_CSV) as f:
        lines = [line.strip() for line in f if not line.startswith("#")]
    names = lines[0].split(",")
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:] if line])
    data = {name: values[:, j] for j, name in enumerate(names)}
    floats = lambda s: np.array([float(v) for v in s.split(",")])  # noqa: E731
    return {
        "rs": float(meta["rs"]),
        "ls": float(meta["ls"]),
        "psi_f": float(meta["psi_f"]),
        "pole_pairs": int(meta["pole_pairs"]),
        "ts": float(meta["ts"]),
        "q": floats(meta["q"]),
        "r": floats(meta["r"]),
        "x0": floats(meta["x0"]),
        "p0": floats(meta["p0"]),
        "u_ab": np.column_stack([data["u_a"], data["u_b"]]),
        "i_ab": np.column_stack([data["z_a"], data["z_b"]]),
        "theta_true": data["th_true"],
        "omega_true": data["w_true"],
    }

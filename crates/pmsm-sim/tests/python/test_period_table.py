"""`pmsm-sim run --csv --parquet`: the per-period table, a row per PWM period with named vector
fields, is the run's MCAP log in columns, and the CSV and the Parquet file hold the same table.
Run as test_mcap.py; needs polars."""
import subprocess

import polars as pl
from polars.testing import assert_frame_equal

from test_mcap import read, sim_bin  # noqa: F401 - the binary fixture


def test_periods_csv_and_parquet_are_the_log(sim_bin, tmp_path):  # noqa: F811
    out = tmp_path / "o"
    done = subprocess.run([sim_bin, "run", "default", "--duration", "0.3", "--out", str(out),
                           "--no-plot", "--csv", "--parquet"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    pq = pl.read_parquet(out / "periods.parquet")
    csv = pl.read_csv(out / "periods.csv", schema=pq.schema)
    assert_frame_equal(csv, pq)
    assert pq.height == 3000
    assert pq.schema["k"] == pl.Int64 and pq.schema["ekf_tracking"] == pl.Boolean
    assert pq.schema["state"] == pl.Utf8 and pq["fault"].null_count() == 3000
    _, messages, _ = read(out / "run.mcap")
    periods = messages["/pmsm_sim/period"]
    assert pq["k"].to_list() == [p["k"] for p in periods]
    assert pq["i_q_a"].to_list() == [p["truth"]["i_dq_a"][1] for p in periods]
    assert pq["i_alpha_meas_a"].to_list() == [p["measured"]["i_ab_a"][0] for p in periods]
    assert pq["duty_c"].to_list() == [p["inverter"]["duties"][2] for p in periods]
    assert pq["state"].to_list() == [p["control"]["telemetry"]["state"] for p in periods]
    assert pq["foc_angle_error_deg"].to_list() == [
        p["controller_observer"]["angle_error_deg"] for p in periods]
    assert set(pq["state"].unique()) >= {"align", "closed_loop"}

"""`pmsm-sim sweep PLAN.toml --out DIR`: its results.parquet is the table pyfoc.sweep returns for
the same plan (same columns, types and values), and Ctrl-C keeps the finished rows.

Run as test_mcap.py (PMSM_SIM_BIN, or a cargo build); needs polars and pyfoc in the venv."""
import signal
import subprocess
import time

import polars as pl
import pytest
from polars.testing import assert_frame_equal

from test_mcap import sim_bin  # noqa: F401 - the binary fixture

PLAN = """
scenario = "default"
n = 3
seed = 5

[vary]
duration_s = 0.3
"motor.rs_ohm" = ["uniform", 2.5, 3.2]
inverter.dead_time_s = [0.0, 1e-6]
"controller.current_limit_a" = [4.5, -1.0]
"""


def test_results_parquet_is_pyfocs_table(sim_bin, tmp_path):  # noqa: F811
    pyfoc = pytest.importorskip("pyfoc")
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN)
    done = subprocess.run([sim_bin, "sweep", str(plan), "--out", str(tmp_path / "out"),
                           "--threads", "2"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "12 of 12 runs" in done.stderr and "(6 failed)" in done.stderr
    got = pl.read_parquet(tmp_path / "out" / "results.parquet")
    want = pyfoc.sweep("default", {
        "duration_s": 0.3,
        "motor.rs_ohm": ("uniform", 2.5, 3.2),
        "inverter.dead_time_s": [0.0, 1e-6],
        "controller.current_limit_a": [4.5, -1.0],
    }, n=3, seed=5)
    assert_frame_equal(got, want)
    assert got["error"].null_count() == 6
    assert got.filter(pl.col("controller.current_limit_a") < 0)["error"].str.contains(
        "controller.current_limit_a").all()


def test_ctrl_c_keeps_the_finished_rows(sim_bin, tmp_path):  # noqa: F811
    plan = tmp_path / "long.toml"
    plan.write_text('scenario = "default"\nn = 5000\nseed = 1\n[vary]\n"motor.rs_ohm" = ["relative", 0.1]\n')
    out = tmp_path / "out"
    proc = subprocess.Popen([sim_bin, "sweep", str(plan), "--out", str(out), "--threads", "2"],
                            stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "SIGINT" in err and "of 5000 runs" in err
    df = pl.read_parquet(out / "results.parquet")
    assert 0 < df.height < 5000
    # Only finished runs: complete, every period simulated, no error; distinct plan indices.
    assert df["end"].to_list() == ["completed"] * df.height
    assert df["simulated_s"].to_list() == [2.0] * df.height
    assert df["error"].null_count() == df.height
    assert df["index"].is_unique().all() and df["index"].max() < 5000


def test_bad_plans_are_named(sim_bin, tmp_path):  # noqa: F811
    for text, want in [
        ('scenario = "default"\nruns = 3\n', "runs: unknown key"),
        ('scenario = "nope"\n', "scenario"),
        ('n = 1\n', "scenario: missing"),
        ('scenario = "default"\n[vary]\n"motor.rs_ohm" = ["uniform", 3.0]\n', "vary.motor.rs_ohm"),
        ('scenario = "default"\nn = -1\n', "n: expected a whole number"),
    ]:
        plan = tmp_path / "bad.toml"
        plan.write_text(text)
        done = subprocess.run([sim_bin, "sweep", str(plan), "--out", str(tmp_path / "o")],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 1, (text, done.stderr)
        assert want in done.stderr and "panicked" not in done.stderr, (text, done.stderr)

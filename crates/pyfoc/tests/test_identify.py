"""pyfoc.identify: self-commissioning of a scenario's motor from Python."""

import json
import tomllib
from pathlib import Path

import pytest

import pyfoc


def test_identify_default_meets_the_goals():
    rep = pyfoc.identify("default")
    assert rep["ok"] and rep["pwm_off_at_end"]
    ident, truth, err = rep["identified"], rep["truth"], rep["errors_pct"]
    for key in ("rs_ohm", "ld_h", "lq_h", "psi_f_wb", "j_kg_m2", "inverter_voltage_error_v"):
        assert key in ident and key in truth
    assert abs(err["rs_ohm"]) < 2.0
    assert abs(err["ld_h"]) < 3.0 and abs(err["lq_h"]) < 3.0
    assert abs(err["psi_f_wb"]) < 1.0
    assert rep["total_time_s"] < 3.0
    assert [s["step"] for s in rep["steps"]][:2] == ["offsets", "probe"]


def test_identify_is_deterministic_per_seed():
    a = pyfoc.identify("drone", seed=4)
    b = pyfoc.identify("drone", seed=4)
    assert a["identified"] == b["identified"] and a["seed"] == 4


def test_failure_is_reported_not_raised():
    # An open phase from the start, through a scenario dict.
    root = Path(__file__).resolve().parents[3]
    text = (root / "crates/pmsm-sim/scenarios/default.toml").read_text()
    d = tomllib.loads(text)
    d["faults"] = [{"kind": "phase_open", "t_s": 0.0, "phase": "b"}]
    rep = pyfoc.identify(d)
    assert not rep["ok"] and rep["error_kind"] == "open_phase"
    assert rep["failed_step"] == "probe" and rep["pwm_off_at_end"]
    assert rep["identified"] is None
    json.dumps(rep)


def test_bad_scenario_raises():
    with pytest.raises(pyfoc.ConfigError):
        pyfoc.identify("no-such-preset")
    with pytest.raises(TypeError):
        pyfoc.identify(42)

"""docs/foxglove-layout.json (the Foxglove layout shipped for pmsm-sim's logs) plots fields that
exist: every message path resolves, on a run's MCAP log read back here, to a value of the right
kind (numbers for plots, any value for the state panel), and every panel is placed in the
layout. Run as test_mcap.py."""
import json
import math
import re
import subprocess

from test_mcap import ROOT, read, sim_bin  # noqa: F401 - the binary fixture

LAYOUT = ROOT / "docs" / "foxglove-layout.json"
PATH = re.compile(r"^(/[a-z_/]+)\.([a-z_.]+)(?:\[(\d)\])?$")


def panels(tree):
    if isinstance(tree, str):
        return [tree]
    return panels(tree["first"]) + panels(tree["second"])


def resolve(message, fields, index):
    value = message
    for f in fields.split("."):
        if value is None:
            return None
        assert f in value, f"{fields}: no field {f!r}"
        value = value[f]
    if index is not None and value is not None:
        value = value[int(index)]
    return value


def test_layout_paths_exist_in_a_log(sim_bin, tmp_path):  # noqa: F811
    layout = json.loads(LAYOUT.read_text())
    assert sorted(panels(layout["layout"])) == sorted(layout["configById"])
    out = tmp_path / "o"
    done = subprocess.run([sim_bin, "run", "default", "--duration", "0.4", "--out", str(out),
                           "--no-plot"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    _, messages, _ = read(out / "run.mcap")
    for panel, config in layout["configById"].items():
        assert config["paths"], panel
        for p in config["paths"]:
            m = PATH.match(p["value"])
            assert m, p["value"]
            topic, fields, index = m.groups()
            values = [resolve(msg, fields, index) for msg in messages[topic]]
            present = [v for v in values if v is not None]
            # (The state panel may show an optional field a healthy run leaves out: the fault.)
            if panel.startswith("Plot!"):
                assert present, f"{panel}: {p['value']} is never set in the log"
                assert all(isinstance(v, float) for v in present), p["value"]
                assert any(math.isfinite(v) and v != 0.0 for v in present), p["value"]
            assert p.get("label"), f"{panel}: {p['value']} has no label"


# The named components of the log's vectors (message path, array path, index).
NAMED = [
    ("truth.i_alpha_a", "truth.i_ab_a", 0), ("truth.i_beta_a", "truth.i_ab_a", 1),
    ("truth.i_d_a", "truth.i_dq_a", 0), ("truth.i_q_a", "truth.i_dq_a", 1),
    ("control.telemetry.i_d_a", "control.telemetry.i_dq_a", 0),
    ("control.telemetry.i_q_a", "control.telemetry.i_dq_a", 1),
    ("control.telemetry.i_d_ref_a", "control.telemetry.i_dq_ref_a", 0),
    ("control.telemetry.i_q_ref_a", "control.telemetry.i_dq_ref_a", 1),
    ("control.telemetry.u_d_ref_v", "control.telemetry.u_dq_ref_v", 0),
    ("control.telemetry.u_q_ref_v", "control.telemetry.u_dq_ref_v", 1),
    ("inverter.u_alpha_v", "inverter.u_ab_v", 0), ("inverter.u_beta_v", "inverter.u_ab_v", 1),
]


def test_named_fields_equal_the_array_components(sim_bin, tmp_path):  # noqa: F811
    out = tmp_path / "o"
    done = subprocess.run([sim_bin, "run", "default", "--duration", "0.2", "--out", str(out),
                           "--no-plot"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    _, messages, _ = read(out / "run.mcap")
    periods = messages["/pmsm_sim/period"]
    assert len(periods) > 1000
    for named, array, i in NAMED:
        values = [resolve(m, named, None) for m in periods]
        assert values == [resolve(m, array, i) for m in periods], named
        assert any(v != 0.0 for v in values), f"{named} is always 0"

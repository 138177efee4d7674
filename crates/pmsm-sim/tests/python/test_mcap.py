"""Reads pmsm-sim's MCAP logs back with the `mcap` Python package (what Foxglove-side tools use).

The per-period channel is protobuf (its schema a FileDescriptorSet), decoded with
`mcap-protobuf-support` (Google's `protobuf` runtime); the other channels are JSON.

Run (from the workspace root):

    python -m pip install -r tests/data/requirements.txt   # mcap, mcap-protobuf-support, pytest
    python -m pytest crates/pmsm-sim/tests/python

The simulator binary is taken from the environment variable PMSM_SIM_BIN when set; otherwise
it is built with `cargo build -p pmsm-sim` (honouring CARGO_TARGET_DIR) and its path read from
cargo's JSON messages.
"""

import json
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

ROOT = Path(__file__).resolve().parents[4]
PERIOD_FIELDS = {
    "k",
    "t_s",
    "truth",
    "measured",
    "observer",
    "seed_filter",
    "controller_observer",
    "control",
    "inverter",
}


@pytest.fixture(scope="session")
def sim_bin() -> str:
    env = os.environ.get("PMSM_SIM_BIN")
    if env:
        return env
    out = subprocess.run(
        ["cargo", "build", "-p", "pmsm-sim", "--bin", "pmsm-sim", "--message-format=json"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    for line in out.splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg.get("executable"):
            if msg["target"]["name"] == "pmsm-sim":
                return msg["executable"]
    raise RuntimeError("cargo built no pmsm-sim executable")


class JsonDecoderFactory(McapDecoderFactory):
    """Decodes the JSON channels (message encoding `json`)."""

    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def to_dict(msg):
    """A decoded protobuf message as the dict of the JSON encoding: the same field names,
    `None` for an absent message or `optional` field, lists for repeated fields."""
    out = {}
    for field in msg.DESCRIPTOR.fields:
        value = getattr(msg, field.name)
        if field.is_repeated:
            out[field.name] = list(value)
        elif field.has_presence and not msg.HasField(field.name):
            out[field.name] = None
        elif field.type == field.TYPE_MESSAGE:
            out[field.name] = to_dict(value)
        else:
            out[field.name] = value
    return out


def read(path: Path):
    """(summary, {topic: [decoded messages as dicts]}, {topic: (schema, channel, last log time)})."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory(), JsonDecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None, "no summary: the file was not finished"
        messages, channels = {}, {}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            if channel.message_encoding == "protobuf":
                decoded = to_dict(decoded)
            messages.setdefault(channel.topic, []).append(decoded)
            channels[channel.topic] = (schema, channel, message.log_time)
    return summary, messages, channels


def time_origin(path: Path):
    """(first message's log time, the `pmsm_sim` metadata) of a log: the origin a reader takes
    the messages' times from."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        first = next(iter(reader.iter_messages(log_time_order=False)))[2]
        meta = next(m.metadata for m in reader.iter_metadata() if m.name == "pmsm_sim")
    return first.log_time, meta


def test_default_run_reads_back(sim_bin, tmp_path):
    out = tmp_path / "o"
    before_ns = time.time_ns()
    done = subprocess.run(
        [sim_bin, "run", "default", "--duration", "0.4", "--out", str(out), "--no-plot"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    summary, messages, channels = read(out / "run.mcap")

    assert set(messages) == {"/pmsm_sim/period", "/pmsm_sim/scenario", "/pmsm_sim/metrics"}
    counts = {summary.channels[i].topic: n for i, n in summary.statistics.channel_message_counts.items()}
    assert counts["/pmsm_sim/period"] == 4000
    for topic, (schema, channel, _) in channels.items():
        if topic == "/pmsm_sim/period":
            # Protobuf, the schema a FileDescriptorSet of pmsm_sim.Period (what Foxglove reads).
            assert channel.message_encoding == "protobuf"
            assert schema.encoding == "protobuf"
            assert schema.name == "pmsm_sim.Period"
        else:
            assert channel.message_encoding == "json"
            assert schema.encoding == "jsonschema"
            assert json.loads(schema.data)["title"].startswith("pmsm_sim.")

    periods = messages["/pmsm_sim/period"]
    assert len(periods) == 4000
    assert set(periods[0]) == PERIOD_FIELDS
    ts = 1e-4
    for i, p in enumerate(periods):
        assert p["k"] == i
        assert math.isclose(p["t_s"], i * ts, rel_tol=1e-12, abs_tol=1e-15)
        assert -math.pi <= p["truth"]["theta_e_rad"] < math.pi
        assert len(p["observer"]["p_diag"]) == 4 and min(p["observer"]["p_diag"]) >= 0.0
        assert all(0.0 <= d <= 1.0 for d in p["inverter"]["duties"])
    # Log time: the run's wall-clock start (the first message's time, recorded as the
    # metadata's start_time_unix_ns) plus the simulated time in ns.
    start, meta = time_origin(out / "run.mcap")
    assert before_ns <= start <= time.time_ns()
    assert meta["start_time_unix_ns"] == str(start)
    assert channels["/pmsm_sim/period"][2] == start + 3999 * 100_000
    last = periods[-1]
    # The default runs foc sensorless: 0.1 s of alignment, I/f, hand-over at 0.335 s.
    states = [p["control"]["telemetry"]["state"] for p in periods]
    assert states[500] == "align" and states[1500] == "open_loop"
    assert last["control"]["telemetry"]["state"] == "closed_loop"
    assert last["control"]["telemetry"]["closed_loop"]
    assert last["control"]["telemetry"]["fault"] is None
    assert last["inverter"]["pwm_enabled"]
    assert abs(last["observer"]["angle_error_deg"]) < 5.0
    assert abs(last["controller_observer"]["angle_error_deg"]) < 5.0
    assert len(last["control"]["telemetry"]["estimate"]["p_diag"]) == 4
    assert last["seed_filter"] is not None
    # The tracked parameters (ekf-core's online tracking) against the plant's: the default
    # scenario's motor is the one the observers are told, so the tracked flux stays at it.
    psi_true, rs_true = last["truth"]["psi_f_wb"], last["truth"]["rs_ohm"]
    assert psi_true == pytest.approx(0.175) and rs_true == pytest.approx(2.875)
    for name in ("observer", "controller_observer"):
        o = last[name]
        assert abs(o["psi_f_wb"] / psi_true - 1.0) < 0.01, (name, o["psi_f_wb"])
        assert 0.0 < o["psi_f_sigma_wb"] <= 0.1 * psi_true * (1 + 1e-6)  # at most the initial 10 %
        assert abs(o["rs_ohm"] / rs_true - 1.0) < 0.05, (name, o["rs_ohm"])
        assert o["rs_sigma_ohm"] > 0.0
        assert abs(o["winding_temperature_c"] - 20.0) < 15.0
    est = last["control"]["telemetry"]["estimate"]
    assert est["psi_f_wb"] == last["controller_observer"]["psi_f_wb"]
    # The seed's filter tracks nothing: the told values, no deviation.
    assert last["seed_filter"]["psi_f_wb"] == pytest.approx(0.175)
    assert last["seed_filter"]["psi_f_sigma_wb"] == 0.0
    scen = messages["/pmsm_sim/scenario"][0]
    assert scen["name"] == "default" and "[motor]" in scen["toml"]
    assert messages["/pmsm_sim/metrics"][0]["periods"] == 4000


def test_protobuf_and_json_encodings_agree(sim_bin, tmp_path):
    """The same run logged with --log-encoding json (JSON schema) and compressed: every period
    message has the same fields and the same numbers as the protobuf one. With --log-time
    zero the time stamps are the simulated time alone (no start time recorded)."""
    logs = {}
    for enc, comp in [("protobuf", "none"), ("json", "zstd"), ("protobuf", "lz4")]:
        out = tmp_path / f"{enc}-{comp}"
        done = subprocess.run(
            [sim_bin, "run", "default", "--duration", "0.05", "--out", str(out), "--no-plot",
             "--log-encoding", enc, "--log-compression", comp, "--log-time", "zero"],
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        _, messages, channels = read(out / "run.mcap")
        assert channels["/pmsm_sim/period"][1].message_encoding == enc
        assert channels["/pmsm_sim/period"][2] == 499 * 100_000
        start, meta = time_origin(out / "run.mcap")
        assert start == 0 and "start_time_unix_ns" not in meta
        logs[(enc, comp)] = messages["/pmsm_sim/period"]
    pb = logs[("protobuf", "none")]
    assert len(pb) == 500
    assert pb == logs[("json", "zstd")]
    assert pb == logs[("protobuf", "lz4")]
    # A message with every optional part present (foc: its estimate and speed reference).
    tel = pb[-1]["control"]["telemetry"]
    assert tel["estimate"] is not None and tel["speed_ref_rpm"] is not None
    assert tel["fault"] is None


def test_interrupted_run_is_readable(sim_bin, tmp_path):
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [sim_bin, "run", "--duration", "1000", "--out", str(out), "--no-plot", "--no-seed-filter"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    log = out / "run.mcap"
    deadline = time.monotonic() + 60
    while not (log.exists() and log.stat().st_size > (2 << 20)):
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    summary, messages, _ = read(log)
    n = len(messages["/pmsm_sim/period"])
    assert n > 1000
    assert messages["/pmsm_sim/period"][-1]["seed_filter"] is None
    assert messages["/pmsm_sim/event"][0]["level"] == "warning"
    assert "interrupted" in messages["/pmsm_sim/event"][0]["message"]
    assert messages["/pmsm_sim/metrics"][0]["periods"] == n


def test_sigterm_run_is_readable(sim_bin, tmp_path):
    """SIGTERM (what `kill`, systemd and container runtimes send) stops the run like Ctrl-C:
    every period simulated so far is in the log, which has its summary, an event and the
    metrics."""
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [sim_bin, "run", "--duration", "1000", "--out", str(out), "--no-plot"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    log = out / "run.mcap"
    deadline = time.monotonic() + 60
    while not (log.exists() and log.stat().st_size > (2 << 20)):
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err  # 128 + SIGTERM
    assert b"interrupted" in err
    summary, messages, _ = read(log)
    periods = messages["/pmsm_sim/period"]
    n = len(periods)
    assert n > 1000
    assert [p["k"] for p in periods] == list(range(n))
    counts = {summary.channels[i].topic: c for i, c in summary.statistics.channel_message_counts.items()}
    assert counts["/pmsm_sim/period"] == n
    assert messages["/pmsm_sim/event"][0]["level"] == "warning"
    assert "interrupted" in messages["/pmsm_sim/event"][0]["message"]
    assert messages["/pmsm_sim/metrics"][0]["periods"] == n


def test_fault_run_logs_the_trip(sim_bin, tmp_path):
    """A scenario with an injected fault (a 5 ms dropout: foc trips non_finite_input after 5
    missing samples) logs the missing samples as NaN and the trip, and stays readable."""
    scen = tmp_path / "dropout.toml"
    text = subprocess.run([sim_bin, "show"], capture_output=True, text=True, check=True).stdout
    scen.write_text(text + '\n[[faults]]\nkind = "dropout"\nt_s = 0.45\nduration_s = 0.005\n')
    out = tmp_path / "o"
    done = subprocess.run(
        [sim_bin, "run", str(scen), "--duration", "0.5", "--out", str(out), "--no-plot"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    _, messages, _ = read(out / "run.mcap")
    periods = messages["/pmsm_sim/period"]
    assert len(periods) == 5000
    assert math.isnan(periods[4500]["measured"]["i_abc_a"][0])
    assert periods[4499]["control"]["telemetry"]["fault"] is None
    assert periods[4504]["control"]["telemetry"]["fault"] == "non_finite_input"
    assert not periods[4504]["inverter"]["pwm_enabled"]
    assert all(0.0 <= d <= 1.0 for p in periods for d in p["inverter"]["duties"])


def test_a_write_error_leaves_a_readable_log(sim_bin, tmp_path):
    """A write error while the log grows (here the file size limit, RLIMIT_FSIZE, which fails
    writes as a full disk does, without root): exit 1 naming the file and the cause; the log is
    cut back to its last complete chunk (1024 periods each) and closed, and reads back here; no
    plot.svg or metrics.json, complete or not, is left."""
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1_500_000, 1_500_000))

    out = tmp_path / "o"
    r = subprocess.run(
        [sim_bin, "run", "--duration", "0.5", "--out", str(out)],
        capture_output=True, text=True, preexec_fn=limit,
    )
    assert r.returncode == 1, r.stderr
    assert "run.mcap" in r.stderr and "File too large" in r.stderr, r.stderr
    assert sorted(os.listdir(out)) == ["run.mcap"], r.stderr
    assert (out / "run.mcap").stat().st_size <= 1_500_000
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory()])
        ks = [m.k for _, _, _, m in reader.iter_decoded_messages(topics=["/pmsm_sim/period"])]
    assert ks == list(range(len(ks))) and len(ks) >= 1024 and len(ks) % 1024 == 0, len(ks)

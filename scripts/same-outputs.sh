#!/usr/bin/env bash
# Behaviour gate for refactors: writes every simulator output that must not change
# into DIR, with the wall-clock fields of the JSON files removed.
#   bash scripts/same-outputs.sh DIR          # after a refactor: diff -r BEFORE DIR
# Runs: the default scenario (metrics, MCAP, plot), suite, faults, identify, tune.
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath -m "${1:?usage: same-outputs.sh DIR}")
rm -rf "$out"; mkdir -p "$out"
cargo build --release --locked -q -p pmsm-sim
sim="${CARGO_TARGET_DIR:-target}/release/pmsm-sim"
# --log-time zero: MCAP time stamps from the simulated time alone (the default, wall, adds the
# run's wall-clock start time), so that the logs' messages compare equal between runs
$sim run --out "$out/run" --json --log-time zero >"$out/run.stdout" 2>/dev/null
$sim identify --out "$out/identify" --json --log-time zero >"$out/identify.stdout" 2>/dev/null
$sim tune "$out/run/run.mcap" --json --max-evals 400 >"$out/tune.stdout" 2>/dev/null
# suite and faults exit 1 when a check fails that is no documented known limit (a result,
# compared like the rest): tolerated here, any other failure stops the gate
$sim suite --out "$out/suite" >"$out/suite.stdout" 2>/dev/null || [ $? -eq 1 ]
$sim faults --out "$out/faults" >"$out/faults.stdout" 2>/dev/null || [ $? -eq 1 ]
# wall-clock and path fields vary between identical runs; MCAP files are compared
# by their messages, schemas and metadata (the summary's clock fields left out)
py=${PYTHON:-python3}; [ -x .venv/bin/python ] && py=.venv/bin/python
"$py" -c "import mcap" 2>/dev/null || { echo "same-outputs.sh: needs the Python package mcap (set PYTHON=... or make .venv: bash scripts/test-all.sh)" >&2; exit 1; }
$py - "$out" <<'PY'
import hashlib, json, pathlib, re, sys
root = pathlib.Path(sys.argv[1])
clock = re.compile(r"(wall|elapsed|real_time|rtf|_ns|_per_s|seconds_taken|duration_wall)", re.I)
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not clock.search(k)}
    if isinstance(v, list):
        return [strip(x) for x in v]
    if isinstance(v, str):
        return v.replace(str(root), "OUT")
    return v
try:
    from mcap.reader import make_reader
except ImportError:
    make_reader = None
for m in list(root.rglob("*.mcap")) if make_reader else []:
    lines = []
    with open(m, "rb") as f:
        r = make_reader(f)
        for schema, channel, msg in r.iter_messages():
            data = msg.data
            if channel.message_encoding == "json":
                data = json.dumps(strip(json.loads(data)), sort_keys=True).encode()
            lines.append(f"{channel.topic} {msg.log_time} {hashlib.sha256(data).hexdigest()[:16]}")
        for md in r.iter_metadata():
            lines.append(f"metadata {md.name} {sorted(md.metadata.items())}")
    m.with_suffix(".mcap.txt").write_text("\n".join(lines) + "\n")
    m.unlink()
for p in list(root.rglob("*.json")) + list(root.glob("*.stdout")) + list(root.rglob("*.md")):
    t = p.read_text()
    try:
        p.write_text(json.dumps(strip(json.loads(t)), indent=1, sort_keys=True))
    except json.JSONDecodeError:
        t = t.replace(str(root), "OUT")
        t = re.sub(r"(real-time factor|RTF|wall time|elapsed)[^\n]*", r"\1 <clock>", t, flags=re.I)
        p.write_text(t)
PY
echo "outputs in $out"

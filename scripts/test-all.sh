#!/usr/bin/env bash
# The one test command (README): installs what it needs, then runs every check.
#   bash scripts/test-all.sh
# Needs rustup and python3 (>= 3.10) on PATH; everything else it installs itself.
set -euo pipefail
cd "$(dirname "$0")/.."
step() { printf '\n=== %s\n' "$*"; }
# A one-shot build: incremental caches would only take disk (the whole run needs about 3 GB).
export CARGO_INCREMENTAL=0

step "toolchain (rust-toolchain.toml) and the Cortex-M4F target"
rustup toolchain install >/dev/null  # the pinned toolchain, with rustfmt and clippy
rustup target add thumbv7em-none-eabihf
rustup component add rustfmt clippy >/dev/null

step "formatting"
cargo fmt --all --check

step "clippy, host, all targets"
cargo clippy --all-targets --locked -- -D warnings

step "no_std build and clippy for thumbv7em-none-eabihf"
cargo clippy -p ekf-core -p foc --no-default-features --target thumbv7em-none-eabihf --locked -- -D warnings
cargo build -p ekf-core -p foc --no-default-features --target thumbv7em-none-eabihf --release --locked

step "Cortex-M4F firmware under QEMU: runs, checks, instruction counts, no f64"
bash scripts/qemu-firmware.sh

step "B-G431B-ESC1 board crate: host tests, clippy and build for thumbv7em-none-eabihf, flash <= 110 KiB, RAM <= 24 KiB"
cargo test --locked -q -p board-b-g431b-esc1 --lib
cargo clippy -p board-b-g431b-esc1 --target thumbv7em-none-eabihf --locked -- -D warnings
bash crates/board-b-g431b-esc1/check-size.sh

step "tests (unit, integration, doc)"
cargo test --locked

step "fuzzing, bounded: every fuzz target of ekf-core and foc for 20 s (release)"
fuzz_log=$(mktemp)
if ! FUZZ_SECONDS=20 cargo test --release --locked -p ekf-core -p foc --test fuzz -- --nocapture >"$fuzz_log" 2>&1; then
    cat "$fuzz_log"
    exit 1
fi
grep -oE 'fuzz [^:]+: [0-9]+ cases in [0-9.]+ s|test result.*' "$fuzz_log"

step "Python venv (.venv): numpy, maturin, pytest, filterpy"
venv=.venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/data/requirements.txt

step "reference fixture is what its checked-in script makes"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$venv/bin/python" tests/data/gen_seed_reference.py --out "$tmp/seed_reference.csv" >"$tmp/gen.log"
"$venv/bin/python" tests/data/compare_csv.py tests/data/seed_reference.csv "$tmp/seed_reference.csv"

step "pyfoc: clippy, build into the venv (maturin), pytest (with mypy.stubtest of pyfoc.pyi)"
cargo clippy -p pyfoc --all-targets --locked -- -D warnings
(cd crates/pyfoc && VIRTUAL_ENV="$PWD/../../$venv" PATH="$PWD/../../$venv/bin:$PATH" maturin develop --locked --quiet)
"$venv/bin/python" -m pytest crates/pyfoc/tests -q

step "pmsm-sim: MCAP log read back by the Python mcap package; the datasheet's HTML in headless Chromium"
# Debian's chromium for the datasheet's rendering test (about 40 s with apt-get update).
if ! command -v chromium >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" = 0 ] || sudo="sudo"
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi
cargo build -p pmsm-sim --locked --quiet
PMSM_REQUIRE_CHROMIUM=1 PMSM_SIM_BIN="$(pwd)/target/debug/pmsm-sim" "$venv/bin/python" -m pytest crates/pmsm-sim/tests/python -q

step "all checks passed"

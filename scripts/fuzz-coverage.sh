#!/usr/bin/env bash
# Runs the fuzz targets of ekf-core and foc for FUZZ_SECONDS each (default 60), built with
# LLVM source-based coverage, and prints the line/region coverage of ekf-core/src and foc/src
# reached by the fuzzing alone.
#   FUZZ_SECONDS=60 bash scripts/fuzz-coverage.sh
set -euo pipefail
cd "$(dirname "$0")/.."
rustup component add llvm-tools >/dev/null
bin="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin"
export CARGO_TARGET_DIR=target/coverage
export RUSTFLAGS="-C instrument-coverage"
export FUZZ_SECONDS="${FUZZ_SECONDS:-60}"
prof=target/coverage/prof
rm -rf "$prof" && mkdir -p "$prof"
export LLVM_PROFILE_FILE="$PWD/$prof/fuzz-%p-%m.profraw"
objects=()
for t in "ekf-core fuzz" "foc fuzz"; do
    set -- $t
    cargo test --release --locked -p "$1" --test "$2" -- --nocapture
    exe=$(cargo test --release --locked -p "$1" --test "$2" --no-run --message-format=json 2>/dev/null |
        sed -n 's/.*"executable":"\([^"]*\)".*/\1/p' | tail -1)
    objects+=(-object "$exe")
done
"$bin/llvm-profdata" merge -sparse "$prof"/*.profraw -o "$prof/fuzz.profdata"
"$bin/llvm-cov" report -instr-profile="$prof/fuzz.profdata" "${objects[@]:1}" \
    --ignore-filename-regex='(\.cargo|rustc|/tests/)' | grep -E 'Filename|ekf-core/src|foc/src|TOTAL|---'

#!/usr/bin/env bash
# Builds the Cortex-M4F firmware example (crates/foc-firmware), runs it under QEMU and checks it:
#   bash scripts/qemu-firmware.sh [--no-install] [--allow-f64]
#
# - Installs what it needs when missing: the thumbv7em-none-eabihf target and the llvm-tools
#   component (rustup; llvm-size and llvm-nm), and Debian's qemu-system-arm (apt-get, as root or
#   through sudo). --no-install only reports what is missing, with the command that installs it.
# - Runs the firmware on QEMU's mps2-an386 (Cortex-M4 with FPU) with -icount shift=10, so every
#   instruction advances virtual time by 1024 ns and the firmware counts instructions with the
#   SysTick (crates/foc-firmware/src/meter.rs). The firmware checks that the observer converged
#   to the known speed and angle and exits non-zero otherwise.
# - Prints the lines `cortex-m4 <name>: <N> instructions/call`, and flash and RAM use; when every
#   check passed, also writes them as JSON to <target dir>/m4f-counts.json (CARGO_TARGET_DIR or
#   target/), the counts `pmsm-sim datasheet` reads.
# - Fails when the ELF holds double-precision soft-float routines (__aeabi_d*, __aeabi_*2d): the
#   Cortex-M4F has a single-precision FPU only, so any f64 on the MCU path is emulated in
#   software. It names the functions that call them. --allow-f64 makes this a warning.
#
# Exit status: 0 all checks passed; 1 a check failed; 2 a tool is missing (with --no-install).
# Environment: CARGO_TARGET_DIR as for cargo (default: target/); QEMU_TIMEOUT_S (default 60).
set -euo pipefail
cd "$(dirname "$0")/.."

target=thumbv7em-none-eabihf
install=1
allow_f64=0
for arg in "$@"; do
    case "$arg" in
        --no-install) install=0 ;;
        --allow-f64) allow_f64=1 ;;
        -h | --help)
            sed -n '2,18p' "$0"
            exit 0
            ;;
        *)
            echo "qemu-firmware.sh: unknown argument '$arg' (see --help)" >&2
            exit 1
            ;;
    esac
done

step() { printf '=== %s\n' "$*"; }
missing() {
    echo "qemu-firmware.sh: $1 is missing; install it with: $2" >&2
    exit 2
}

step "tools"
# The toolchain of rust-toolchain.toml, its Cortex-M4F target and llvm-tools (llvm-size, llvm-nm).
if [ "$install" = 1 ]; then
    # The pinned toolchain (rustup >= 1.28 no longer installs it on first use; older ones do).
    rustup toolchain install >/dev/null 2>&1 || true
    rustup target add "$target" >/dev/null 2>&1 || rustup target add "$target"
    rustup component add llvm-tools >/dev/null 2>&1 || rustup component add llvm-tools
fi
llvm_bin="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin"
for tool in llvm-size llvm-nm llvm-objdump; do
    [ -x "$llvm_bin/$tool" ] || missing "$tool" "rustup component add llvm-tools"
done
if ! command -v qemu-system-arm >/dev/null 2>&1; then
    [ "$install" = 1 ] || missing qemu-system-arm "sudo apt-get install -y qemu-system-arm"
    sudo=""
    if [ "$(id -u)" != 0 ]; then
        command -v sudo >/dev/null 2>&1 || missing qemu-system-arm "apt-get install -y qemu-system-arm (as root)"
        sudo="sudo"
    fi
    echo "installing qemu-system-arm (apt-get)"
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends qemu-system-arm >/dev/null
fi
qemu-system-arm --version | sed -n 1p

step "build (release, $target)"
cargo build -p foc-firmware --release --target "$target" --locked
elf="${CARGO_TARGET_DIR:-target}/$target/release/foc-firmware"

step "run under QEMU (mps2-an386, -icount shift=10)"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
timeout "${QEMU_TIMEOUT_S:-60}" qemu-system-arm \
    -machine mps2-an386 -cpu cortex-m4 -nographic -monitor none -serial none \
    -icount shift=10 \
    -semihosting-config enable=on,target=native \
    -kernel "$elf" </dev/null >"$log" 2>&1 || status=$?
cat "$log"
fail=0
if [ "$status" = 124 ]; then
    echo "FAIL: the firmware did not exit within ${QEMU_TIMEOUT_S:-60} s (hung or hard fault)"
    fail=1
elif [ "$status" != 0 ]; then
    echo "FAIL: the firmware exited with status $status"
    fail=1
fi
for name in ekf_step foc_tick identify_tick; do
    if ! grep -Eq "^cortex-m4 $name: [0-9]+ instructions/call$" "$log"; then
        echo "FAIL: no 'cortex-m4 $name: <N> instructions/call' line"
        fail=1
    fi
done
grep -q '^foc-firmware: all checks passed$' "$log" || fail=1

step "flash and RAM use"
# Flash: what is loaded at 0x0 (vectors, code, constants, .data's initial values).
# RAM: static data (.data, .bss, .uninit); the stack (top of RAM, growing down) is not included.
mem=$("$llvm_bin/llvm-size" -A "$elf" | awk '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2; f = f sprintf(" %s %d", $1, $2) }
    $1 == ".data" { flash += $2; ram += $2; f = f sprintf(" .data %d", $2); r = r sprintf(" .data %d", $2) }
    $1 == ".bss" || $1 == ".uninit" { ram += $2; r = r sprintf(" %s %d", $1, $2) }
    END {
        printf "cortex-m4 flash: %d bytes (%s )\n", flash, f
        printf "cortex-m4 ram: %d bytes static (%s ; stack not included)\n", ram, r
    }')
echo "$mem"

step "no f64 arithmetic on the MCU (no double-precision soft-float routines)"
# AEABI names (__aeabi_dadd, __aeabi_d2f, __aeabi_f2d, ...) and the libgcc names of
# compiler-builtins (__adddf3, __extendsfdf2, ...).
f64_re='^__aeabi_(d[a-z0-9]+|[a-z0-9]+2d)$|__(add|sub|mul|div)df3$|__(extendsfdf2|truncdfsf2)$|__fix(uns)?df[sdt]i$|__float(un)?[sdt]idf$|__(eq|ne|lt|le|gt|ge|un|cmp)df2$'
f64_syms=$("$llvm_bin/llvm-nm" -C "$elf" | awk '{ print $NF }' | grep -E "$f64_re" | sort -u | tr '\n' ' ' || true)
if [ -z "$f64_syms" ]; then
    echo "ok: no double-precision routines in the ELF"
else
    echo "f64 soft-float routines in the ELF: $f64_syms"
    echo "called from (calls per function):"
    "$llvm_bin/llvm-objdump" -d --no-show-raw-insn -C "$elf" | awk '
        /^[0-9a-f]+ <.*>:$/ { fn = $0; sub(/^[0-9a-f]+ </, "", fn); sub(/>:$/, "", fn); sub(/::h[0-9a-f]+( .*)?$/, "", fn); next }
        /<__aeabi_d[a-z0-9]+>|<__aeabi_[a-z0-9]+2d>|__(add|sub|mul|div)df3[>:]|__(extendsfdf2|truncdfsf2)[>:]/ {
            if (fn !~ /^__aeabi_|compiler_builtins/) n[fn]++
        }
        END { for (f in n) printf "    %4d  %s\n", n[f], f }' | sort -rn
    if [ "$allow_f64" = 1 ]; then
        echo "warning: f64 on the MCU path (allowed by --allow-f64)"
    else
        echo "FAIL: f64 on the MCU path (use --allow-f64 to report only)"
        fail=1
    fi
fi

if [ "$fail" != 0 ]; then
    step "FAILED"
    exit 1
fi
# The counts as JSON for `pmsm-sim datasheet` (only from a run whose checks all passed).
counts="${CARGO_TARGET_DIR:-target}/m4f-counts.json"
flash=$(echo "$mem" | sed -n -E 's/^cortex-m4 flash: ([0-9]+) bytes.*/\1/p')
ram=$(echo "$mem" | sed -n -E 's/^cortex-m4 ram: ([0-9]+) bytes.*/\1/p')
{
    printf '{\n  "machine": "mps2-an386",\n  "qemu": "%s",\n  "instructions_per_call": {' \
        "$(qemu-system-arm --version | sed -n 1p | sed 's/["\\]//g')"
    sed -n -E 's/^cortex-m4 ([a-z_0-9]+): ([0-9]+) instructions\/call$/"\1": \2/p' "$log" | paste -sd, - | sed 's/,/, /g'
    printf '},\n  "flash_bytes": %s,\n  "ram_bytes": %s\n}\n' "${flash:-null}" "${ram:-null}"
} >"$counts"
echo "counts written to $counts"
step "firmware checks passed"

#!/usr/bin/env bash
# Builds the B-G431B-ESC1 firmware (profile `board`, thumbv7em-none-eabihf), prints its flash
# and static RAM use and fails above the limits:
#   bash crates/board-b-g431b-esc1/check-size.sh [--table] [cargo feature arguments...]
#
# flash = .vector_table + .text + .rodata + .data (initial values); RAM = .data + .bss +
# .uninit (the stack, at the top of RAM, is not included). Limits: flash <= 110 KiB,
# RAM <= 24 KiB (the STM32G431CB has 128 KiB and 32 KiB; the last flash page holds the motor
# record). --table builds every feature set of the crate README's table and prints one row
# each (the limits apply to the default set only).
# Needs llvm-size from rustup's llvm-tools component (installed when missing).
# Environment: CARGO_TARGET_DIR as for cargo.
set -euo pipefail
cd "$(dirname "$0")/../.."
target=thumbv7em-none-eabihf
flash_max=$((110 * 1024))
ram_max=$((24 * 1024))

rustup component add llvm-tools >/dev/null 2>&1 || rustup component add llvm-tools
llvm_size="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-size"
[ -x "$llvm_size" ] || { echo "check-size.sh: llvm-size missing (rustup component add llvm-tools)" >&2; exit 2; }
elf="${CARGO_TARGET_DIR:-target}/$target/board/board-b-g431b-esc1"

# Prints "<flash> <ram>" in bytes for the ELF just built.
measure() {
    "$llvm_size" -A "$elf" | awk '
        $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
        $1 == ".data" { flash += $2; ram += $2 }
        $1 == ".bss" || $1 == ".uninit" { ram += $2 }
        END { printf "%d %d\n", flash, ram }'
}

kib() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 1024 }'; }

build() {
    cargo build -p board-b-g431b-esc1 --profile board --target "$target" --locked --quiet "$@"
}

if [ "${1:-}" = "--table" ]; then
    echo "| features | flash (bytes) | flash (KiB) | static RAM (bytes) |"
    echo "|---|---|---|---|"
    for set in "" "tracking" "identify" "identify,tracking" "identify,tracking,field-weakening" "identify,tracking,hfi" "hfi,identify,field-weakening,tracking"; do
        build --no-default-features --features "$set"
        read -r flash ram < <(measure)
        printf '| %s | %d | %s | %d |\n' "${set:-(none)}" "$flash" "$(kib "$flash")" "$ram"
    done
    exit 0
fi

build "$@"
read -r flash ram < <(measure)
printf 'b-g431b-esc1 flash: %d bytes (%s KiB, limit %d KiB)\n' "$flash" "$(kib "$flash")" $((flash_max / 1024))
printf 'b-g431b-esc1 ram: %d bytes static (%s KiB, limit %d KiB; stack not included)\n' "$ram" "$(kib "$ram")" $((ram_max / 1024))
fail=0
[ "$flash" -le "$flash_max" ] || { echo "FAIL: flash above $((flash_max / 1024)) KiB"; fail=1; }
[ "$ram" -le "$ram_max" ] || { echo "FAIL: static RAM above $((ram_max / 1024)) KiB"; fail=1; }
exit "$fail"

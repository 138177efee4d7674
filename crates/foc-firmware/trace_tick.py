#!/usr/bin/env python3
"""Where the instructions of the closed-loop `foc` tick go: an instruction trace under QEMU.

    cargo build -p foc-firmware --release --target thumbv7em-none-eabihf --features trace
    python3 crates/foc-firmware/trace_tick.py $CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/foc-firmware

The `trace` build runs only the surface drive of `drive::run` and calls `drive::trace::begin`
(with a marker call when the tick is a closed-loop one) and `drive::trace::end` around every
counted tick. QEMU (`-icount shift=10`, as for the counts) logs every executed translation
block (`-d exec,in_asm,nochain`); this script counts the instructions executed between a
closed-loop `begin` marker and the next `end`, and attributes each one to the source line the
ELF's line table gives for its address (`llvm-objdump -l`; code inlined from another function
is attributed to that function's line). Instructions of the observer step
(`PmsmObserver::step` and everything it calls) are summed apart, whatever file they come from.

Prints per-tick means: the total (it includes the measurement frame, which the meter's count
subtracts), the observer step, and the rest by source file and by source line; and both by
instruction class (`profile_step.insn_class`). Standard
library only; needs `qemu-system-arm` and `llvm-objdump` (rustup's llvm-tools).
"""

import collections
import os
import re
import subprocess
import sys
import tempfile
import threading

from profile_step import insn_class, mnemonic  # same directory


def llvm_objdump():
    sysroot = subprocess.run(["rustc", "--print", "sysroot"], capture_output=True, text=True,
                             check=True).stdout.strip()
    host = re.search(r"host: (\S+)", subprocess.run(["rustc", "-vV"], capture_output=True,
                                                    text=True, check=True).stdout).group(1)
    return os.path.join(sysroot, "lib", "rustlib", host, "bin", "llvm-objdump")


def line_table(elf):
    """addr -> (function, 'file:line', mnemonic), and function name -> (start, end)."""
    out = subprocess.run([llvm_objdump(), "-d", "-l", "-C", "--no-show-raw-insn", elf],
                         capture_output=True, text=True, check=True).stdout
    where = {}
    funcs = {}
    func, src, start, last = None, "?", None, None
    fhead = re.compile(r"^([0-9a-f]+) <(.*)>:$")
    insn = re.compile(r"^\s+([0-9a-f]+):\s+(\S+)")
    for line in out.splitlines():
        m = fhead.match(line)
        if m:
            if func is not None and start is not None:
                funcs[func] = (start, last + 4)
            func, start, last, src = m.group(2), int(m.group(1), 16), int(m.group(1), 16), "?"
            continue
        if line.startswith("; ") and ":" in line:
            src = line[2:].strip()
            continue
        m = insn.match(line)
        if m and func is not None:
            a = int(m.group(1), 16)
            where[a] = (func, src, mnemonic(m.group(2)))
            last = a
    if func is not None and start is not None:
        funcs[func] = (start, last + 4)
    return where, funcs


def find(funcs, *needles):
    hits = [(name, r) for name, r in funcs.items() if all(n in name for n in needles)]
    if len(hits) != 1:
        sys.exit(f"trace_tick: expected one function matching {needles}, found {[h[0] for h in hits]}")
    return hits[0][1]


def short(src):
    src = re.sub(r"^.*/(crates/[^/]+/src/)", r"\1", src)
    src = re.sub(r"^.*/(library/[^/]+/src/)", r"\1", src)
    return re.sub(r"^.*/\.cargo/registry/src/[^/]+/", "", src)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    elf = sys.argv[1]
    where, funcs = line_table(elf)
    on_mark = find(funcs, "drive::trace::on_mark")[0]
    end_mark = find(funcs, "drive::trace::end")[0]
    # The step's instances (the tick's, and the firmware's own for the split count).
    obs_entries = {r[0] for name, r in funcs.items()
                   if "PmsmObserver" in name and re.search(r"::step(::|$)", name)}
    tick_lo, tick_hi = find(funcs, "foc::controller::Foc::tick")

    with tempfile.TemporaryDirectory() as tmp:
        fifo = os.path.join(tmp, "log")
        os.mkfifo(fifo)
        qemu = subprocess.Popen(
            ["qemu-system-arm", "-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic",
             "-monitor", "none", "-serial", "none", "-icount", "shift=10",
             "-semihosting-config", "enable=on,target=native", "-kernel", elf,
             "-d", "exec,in_asm,nochain", "-D", fifo],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        console = []
        reader = threading.Thread(target=lambda: console.extend(qemu.stdout), daemon=True)
        reader.start()

        blocks = {}  # (pc, flags, cflags) of a translation block -> instruction addresses
        cur = None
        active = in_obs = False
        ticks = 0
        obs = 0
        by_src = collections.Counter()
        by_func = collections.Counter()
        # Instruction classes of the observer step and of the rest.
        cls_obs, cls_rest = collections.Counter(), collections.Counter()
        exec_re = re.compile(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/([0-9a-f]+)/([0-9a-f]+)\]")
        asm_re = re.compile(r"^0x([0-9a-f]+):\s")
        with open(fifo) as log:
            for line in log:
                m = exec_re.match(line)
                if m:
                    pc = int(m.group(1), 16)
                    # A translation block is keyed by its pc, flags and compile flags: under
                    # `-icount` the same pc is also translated into shorter blocks. Its
                    # listing (`in_asm`) comes right before its first execution.
                    key = (pc, m.group(2), m.group(3))
                    if cur and cur[0] == pc:
                        blocks[key] = cur
                    cur = None
                    if pc == on_mark:
                        active, in_obs = True, False
                        continue
                    if pc == end_mark:
                        if active:
                            ticks += 1
                        active = False
                        continue
                    if not active:
                        continue
                    if pc in obs_entries:
                        in_obs = True
                    elif tick_lo <= pc < tick_hi:
                        in_obs = False
                    addrs = blocks.get(key, [pc])
                    if in_obs:
                        obs += len(addrs)
                        for a in addrs:
                            cls_obs[insn_class(where.get(a, ("?", "?", "?"))[2])] += 1
                    else:
                        for a in addrs:
                            f, s, op = where.get(a, ("?", "?", "?"))
                            by_src[short(s)] += 1
                            by_func[f] += 1
                            cls_rest[insn_class(op)] += 1
                    continue
                if line.startswith("IN:"):
                    cur = []
                    continue
                m = asm_re.match(line)
                if m and cur is not None:
                    cur.append(int(m.group(1), 16))
        qemu.wait()
        reader.join()
    print("".join(l for l in console if l.startswith(("foc_tick", "cortex-m4 foc_tick"))), end="")
    if ticks == 0:
        sys.exit("trace_tick: no closed-loop tick traced")
    rest = sum(by_src.values())
    print(f"traced closed-loop ticks: {ticks}")
    print(f"per tick: total {(obs + rest) / ticks:.1f} (with the measurement frame), "
          f"observer step {obs / ticks:.1f}, rest {rest / ticks:.1f}")
    by_file = collections.Counter()
    for s, n in by_src.items():
        by_file[s.rsplit(":", 1)[0]] += n
    print("\nrest by file (instructions per tick):")
    for f, n in by_file.most_common():
        print(f"  {n / ticks:8.1f}  {f}")
    print("\nrest by function (instructions per tick):")
    for f, n in by_func.most_common(25):
        print(f"  {n / ticks:8.1f}  {f}")
    print("\nby instruction class (instructions per tick): observer step / rest")
    for k in sorted(set(cls_obs) | set(cls_rest), key=lambda k: -(cls_obs[k] + cls_rest[k])):
        print(f"  {cls_obs[k] / ticks:8.1f}  {cls_rest[k] / ticks:8.1f}  {k}")
    print("\nrest by source line (instructions per tick, >= 1):")
    for s, n in sorted(by_src.items()):
        if n / ticks >= 1.0:
            print(f"  {n / ticks:8.1f}  {s}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Where the instructions of one observer step go on the Cortex-M4F (QEMU execution trace).

Usage (from the workspace root; CARGO_TARGET_DIR as for cargo, default target/):

    python3 crates/foc-firmware/profile_step.py [default|untracked|seed]

Builds foc-firmware with EKF_PROFILE=<config> (the firmware then runs 1500 steps of that
observer and exits), runs it under QEMU with `-d in_asm,exec,nochain`, takes the instructions
executed by the last call of `PmsmObserver::step`, and prints them by ekf-core function
(innermost inlined frame, from addr2line -i), by path below `step`, and by instruction class.
Needs qemu-system-arm, addr2line (binutils) and rustup's llvm-tools. Temporary files go to a
temporary directory that is deleted at the end. Rebuild the firmware without EKF_PROFILE
afterwards (`cargo bench -p benches --bench cortex_m4` does).
"""
import collections
import os
import re
import subprocess
import sys
import tempfile

TARGET = "thumbv7em-none-eabihf"


def mnemonic(op):
    """The mnemonic without its condition and size suffixes (`vmla.f32` -> `vmla`)."""
    return re.sub(r"(eq|ne|gt|ge|lt|le|ls|hi|mi|pl|hs|lo)?(\.f32|\.w|\.s32)*$", "", op)


def insn_class(op):
    """The class of a Thumb-2 / VFP mnemonic (see `mnemonic`) in the cost maps' tables."""
    if op in ("vadd", "vsub", "vmul", "vmla", "vmls", "vnmul", "vdiv", "vneg", "vabs"):
        return "FP arithmetic"
    if op in ("vcmp", "vcmpe", "vmrs"):
        return "FP compare"
    if op in ("vldr", "ldr", "ldrb", "ldrh", "ldrd", "ldm", "vldm", "pop", "vpop"):
        return "load"
    if op in ("vstr", "str", "strb", "strh", "strd", "stm", "vstm", "push", "vpush"):
        return "store"
    if op in ("vmov", "mov", "movs", "movw", "movt", "mvn"):
        return "move"
    if op.startswith("b") or op.startswith("it") or op in ("cmp", "tst", "cbz", "cbnz"):
        return "branch / IT / compare"
    return "integer, other"


def main():
    which = sys.argv[1] if len(sys.argv) > 1 else "default"
    env = dict(os.environ, EKF_PROFILE=which)
    subprocess.run(["cargo", "build", "-p", "foc-firmware", "--release", "--target", TARGET],
                   check=True, env=env)
    elf = os.path.join(os.environ.get("CARGO_TARGET_DIR", "target"), TARGET, "release",
                       "foc-firmware")
    sysroot = subprocess.run(["rustc", "--print", "sysroot"], capture_output=True, text=True,
                             check=True).stdout.strip()
    host = re.search(r"host: (\S+)", subprocess.run(["rustc", "-vV"], capture_output=True,
                                                     text=True).stdout).group(1)
    llvm = os.path.join(sysroot, "lib", "rustlib", host, "bin")
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "qemu.log")
        subprocess.run(["qemu-system-arm", "-machine", "mps2-an386", "-cpu", "cortex-m4",
                        "-nographic", "-monitor", "none", "-serial", "none", "-icount",
                        "shift=10", "-semihosting-config", "enable=on,target=native",
                        "-kernel", elf, "-d", "in_asm,exec,nochain", "-D", log],
                       stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, timeout=600,
                       check=True)
        tbs, cur = {}, None
        trace = []
        with open(log) as f:
            for line in f:
                if line.startswith("IN:"):
                    cur = []
                    continue
                m = re.match(r"0x([0-9a-f]{8}):", line)
                if m and cur is not None:
                    cur.append(int(m.group(1), 16))
                    continue
                if cur is not None and not line.strip() and cur:
                    tbs[cur[0]] = cur
                    cur = None
                m = re.match(r"Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/", line)
                if m:
                    trace.append(int(m.group(1), 16))
    syms = []
    nm = subprocess.run([os.path.join(llvm, "llvm-nm"), "-C", "-S", elf], capture_output=True,
                        text=True, check=True).stdout
    for line in nm.splitlines():
        p = line.split(None, 3)
        if len(p) == 4 and p[2] in "tT":
            syms.append((int(p[0], 16), int(p[1], 16), p[3]))

    def fn(a):
        for s0, size, name in syms:
            if s0 <= a < s0 + size:
                return name
        return "?"

    entry = {s for s, _, n in syms if "PmsmObserver" in n and "::step" in n}
    last = max(i for i, pc in enumerate(trace) if pc in entry)
    out = []
    for pc in trace[last:]:
        tb = tbs.get(pc, [pc])
        if any("foc_firmware" in fn(a) for a in tb):
            out.extend(a for a in tb if "foc_firmware" not in fn(a))
            break
        out.extend(tb)
    cnt = collections.Counter(out)
    a2l = subprocess.run(["addr2line", "-a", "-i", "-f", "-C", "-e", elf]
                         + [hex(a) for a in sorted(cnt)], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    chains, cur_a, i = {}, None, 0
    while i < len(a2l):
        if a2l[i].startswith("0x"):
            cur_a = int(a2l[i], 16)
            chains[cur_a] = []
            i += 1
            continue
        chains[cur_a].append(a2l[i])
        i += 2
    dis = subprocess.run([os.path.join(llvm, "llvm-objdump"), "-d", "--no-show-raw-insn", elf],
                         capture_output=True, text=True, check=True).stdout
    ops = {int(m.group(1), 16): m.group(2)
           for m in re.finditer(r"^\s+([0-9a-f]+):\s+(\S+)", dis, re.M)}

    def name(f):
        return re.sub(r"<.*?>", "", f).replace("ekf_core::", "")

    inner, path, cls = collections.Counter(), collections.Counter(), collections.Counter()
    fp = collections.Counter()
    for a, c in cnt.items():
        ek = [name(f) for f in chains.get(a, []) if "ekf_core" in f]
        inner[ek[0] if ek else "?"] += c
        outer = list(reversed(ek))
        path[" > ".join(outer[1:3]) if len(outer) > 1 else (outer[0] if outer else "?")] += c
        op = mnemonic(ops.get(a, "?"))
        k = insn_class(op)
        if k == "FP arithmetic":
            fp[op] += c
        cls[k] += c
    print(f"{which}: {len(out)} instructions in the last step")
    for title, table in (("by ekf-core function (innermost inlined frame)", inner),
                         ("by path below step", path), ("by instruction class", cls),
                         ("FP arithmetic by mnemonic (vmla/vmls: a multiply and an add)", fp)):
        print(f"--- {title}")
        for k, c in table.most_common():
            print(f"{c:5d}  {k}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Worst-case stack depth of a Cortex-M (Thumb) firmware ELF, from its disassembly.

Usage: python3 scripts/stack-depth.py [--ram KIB] [--root REGEX] [--top N] ELF

Each function's frame is what its prologue reserves: `push`/`stmdb sp!` (4 B a register),
`vpush` (8 B a d register, 4 B an s register) and `sub sp, #N` (every such instruction in the
body is added, so a frame that grows in two steps counts both). The call graph is every direct
`bl`/`b` to another function's first instruction (a tail call counts as a call: an upper
bound). The worst case from the root (default: cortex-m-rt's `main`) is the deepest path
through that graph, printed with each frame. Static RAM (`scripts/sizes.py`) comes on top.

A function whose address the body loads from a literal pool counts as called (opt-level "z"
calls a function used several times through a register). What it cannot see (printed): other
indirect calls (`blx rN`: trait objects, function pointers; the count per function on the
worst path), recursion (a cycle is cut and named), and frames
sized at run time (`sub sp, rN`: flagged). The interrupt handlers' frames come on top of the
deepest point when an interrupt arrives there.

Why not a crate: `cargo-call-stack` needs a nightly compiler and `-Z emit-stack-sizes`; the
project builds on stable (rust-toolchain.toml). Uses rustup's `llvm-tools` component (listed
in rust-toolchain.toml) or an `llvm-objdump` on the PATH. scripts/test.sh runs it on the
OpenCM 9.04 build with `--ram 20`.

With `--ram KIB`: exits 1 when the worst case plus static RAM exceeds the board's RAM.
"""

import argparse
import os
import re
import shutil
import struct
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sizes import sections, RAM_BASE  # noqa: E402

SHF_ALLOC = 0x2


def objdump():
    """llvm-objdump of rustup's llvm-tools component (the compiler's LLVM; rust-toolchain.toml
    installs it), else the one on the PATH."""
    run = lambda *a: subprocess.run(["rustc", *a], capture_output=True, text=True).stdout.strip()
    cand = os.path.join(run("--print", "sysroot"), "lib", "rustlib", run("--print", "host-tuple"),
                        "bin", "llvm-objdump")
    if os.path.exists(cand):
        return cand
    found = shutil.which("llvm-objdump")
    if found:
        return found
    sys.exit("llvm-objdump not found (rustup component add llvm-tools, or apt-get install llvm)")


def reg_bytes(regs):
    """Bytes a push/vpush register list takes: r/s registers 4 B, d registers 8 B."""
    n = 0
    for r in regs.split(","):
        r = r.strip()
        width = 8 if r.startswith("d") else 4
        if "-" in r:
            a, b = r.split("-")
            n += (int(b[1:]) - int(a[1:]) + 1) * width
        else:
            n += width
    return n


def words(elf):
    """A function reading the 32-bit little-endian word at a virtual address of the ELF."""
    with open(elf, "rb") as fh:
        data = fh.read()
    shoff, = struct.unpack_from("<I", data, 0x20)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x2E)
    spans = []
    for i in range(shnum):
        (_n, typ, _f, addr, off, size) = struct.unpack_from("<IIIIII", data, shoff + i * shentsize)
        if typ == 1 and addr:  # SHT_PROGBITS at an address
            spans.append((addr, off, size))

    def read(addr):
        for (a, off, size) in spans:
            if a <= addr and addr + 4 <= a + size:
                return struct.unpack_from("<I", data, off + addr - a)[0]
        return None

    return read


def graph(elf):
    """(frame bytes, callees, indirect call count, dynamic frame) of each function. Callees are
    the direct `bl`/`b` targets and every function whose address the body loads from a literal
    pool (`ldr rN, [pc, #…]`: at opt-level "z" a repeated call goes through a register)."""
    dis = subprocess.run([objdump(), "-d", "--no-show-raw-insn", elf],
                         capture_output=True, text=True, check=True).stdout
    starts = {}
    for line in dis.splitlines():
        m = re.match(r"^([0-9a-f]+) <(.*)>:", line)
        if m and not m.group(2).startswith("$"):
            starts[int(m.group(1), 16)] = m.group(2)
    read = words(elf)
    frame, calls, indirect, dynamic = {}, {}, {}, set()
    fn = None
    for line in dis.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:", line)
        if m and m.group(1).startswith("$"):
            continue  # a mapping symbol ($t code, $d literal pool): the function goes on
        if m:
            fn = m.group(1)
            frame[fn], calls[fn], indirect[fn] = 0, set(), 0
            continue
        lit = re.search(r"\bldr(?:\.w)?\s+\w+,\s*\[pc.*@\s*0x([0-9a-f]+)", line)
        if fn is not None and lit:
            word = read(int(lit.group(1), 16))
            target = starts.get(word & ~1) if word is not None and word & 1 else None
            if target and target != fn:
                calls[fn].add(target)
        parts = line.split("\t")
        if fn is None or len(parts) < 3:
            continue
        op, args = parts[1].strip(), parts[2].strip()
        if op in ("push", "push.w") or (op in ("stmdb", "stmdb.w") and args.startswith("sp!")):
            frame[fn] += reg_bytes(re.search(r"\{(.*)\}", args).group(1))
        elif op in ("vpush", "vpush.w"):
            frame[fn] += reg_bytes(re.search(r"\{(.*)\}", args).group(1))
        elif op in ("sub", "sub.w", "subw", "subs") and re.match(r"sp,\s*(sp,\s*)?", args):
            imm = re.search(r"#(0x[0-9a-f]+|\d+)", args)
            if imm:
                frame[fn] += int(imm.group(1), 0)
            else:
                dynamic.add(fn)
        elif op in ("blx",) and "<" not in args:
            indirect[fn] += 1
        elif re.fullmatch(r"b(l|eq|ne|cs|cc|mi|pl|vs|vc|hi|ls|ge|lt|gt|le|al)?(\.w)?", op):
            target = re.search(r"<([^>+]*)>", args)
            if target and target.group(1) != fn:
                calls[fn].add(target.group(1))
    return frame, calls, indirect, dynamic


def worst(frame, calls, root):
    """The deepest path from `root`: (bytes, [functions]); cycles cut and named."""
    memo = {}

    def depth(f, onstack):
        if f in memo:
            return memo[f]
        if f in onstack:
            return 0, [f"<cycle back to {short(f)}>"]
        best = (0, [])
        for c in sorted(calls.get(f, ())):
            if c in frame:
                d = depth(c, onstack | {f})
                if d[0] > best[0]:
                    best = d
        r = (frame.get(f, 0) + best[0], [f] + best[1])
        memo[f] = r
        return r

    return depth(root, frozenset())


def short(sym):
    """A mangled Rust symbol without its hash, shortened."""
    return re.sub(r"17h[0-9a-f]{16}E$", "", sym)[:120]


def static_ram(elf):
    """.data + .bss + .uninit bytes (as scripts/sizes.py counts them)."""
    return sum(size for (_n, _t, flags, addr, size) in sections(elf)
               if flags & SHF_ALLOC and addr >= RAM_BASE)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("elf")
    ap.add_argument("--root", default=r"__cortex_m_rt_main17h|^main$")
    ap.add_argument("--ram", type=float, help="the board's RAM, KiB: exit 1 when it does not fit")
    ap.add_argument("--top", type=int, default=8, help="largest frames to list")
    a = ap.parse_args()
    frame, calls, indirect, dynamic = graph(a.elf)
    roots = [f for f in frame if re.search(a.root, f)]
    if not roots:
        sys.exit(f"no function matches --root {a.root!r}")
    total, path = worst(frame, calls, roots[0])
    static = static_ram(a.elf)
    budget = int(a.ram * 1024) if a.ram is not None else None
    code = 0 if budget is None or total + static <= budget else 1
    try:
        report(a, total, path, static, budget, frame, indirect, dynamic)
    except BrokenPipeError:
        # The reader (`| head`) stopped early: the verdict stands, the rest goes nowhere.
        sys.stdout = None
    return code


def report(a, total, path, static, budget, frame, indirect, dynamic):
    """Prints the worst case, its path, the largest frames and the verdict against `budget`."""
    roots = [path[0]] if path else ["?"]
    print(f"{a.elf}: worst-case stack {total:,} B from {short(roots[0])}; static RAM {static:,} B;"
          f" together {total + static:,} B")
    acc = 0
    for f in path:
        acc += frame.get(f, 0)
        notes = []
        if indirect.get(f):
            notes.append(f"{indirect[f]} call(s) through a register")
        if f in dynamic:
            notes.append("run-time sized frame")
        print(f"  {frame.get(f, 0):>7,} {acc:>8,}  {short(f)}" + (f"  ({'; '.join(notes)})" if notes else ""))
    print(f"largest frames:")
    for size, f in sorted(((v, k) for k, v in frame.items()), reverse=True)[:a.top]:
        print(f"  {size:>7,}  {short(f)}")
    if budget is not None:
        verdict = "fits" if total + static <= budget else "does NOT fit"
        print(f"RAM {budget:,} B: {verdict} ({budget - total - static:+,} B)")


if __name__ == "__main__":
    sys.exit(main())

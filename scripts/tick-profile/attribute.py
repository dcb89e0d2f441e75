#!/usr/bin/env python3
"""Attributes a per-address instruction count (gate.c's output) to the firmware's code.

Usage: attribute.py ELF COUNTS TICKS MODE [N] [PATTERN]
  MODE functions  instructions per tick by symbol (llvm-nm; inlined code counts for its caller)
       lines      by source line, the innermost inline frame (llvm-symbolizer)
       stack      by the innermost four inline frames (file:line < file:line < …)
       calls      calls per tick of the functions matching the regex PATTERN, by call site
                  (e.g. 'memcpy|memclr' — who copies; llvm-objdump)
       crates     instructions per tick by the crate whose code runs: the innermost inline
                  frame in one of the project's crates or a maths crate (core's inlined code
                  counts for its caller); the runtime helpers (memcpy, soft-float, …; the
                  COUNTS file's "H" lines, gate.c's PROF_HELPERS) for their call site's crate.
                  Sums the library calls (gait-core, dxl, libm, micromath, fixed) and the loop
                  (the firmware, the contract crate, the bench's tick meter, anything else),
                  and the loop with the dxl master's own code (dxl/src/master.rs, beside the
                  codec it calls: the master's transaction logic)
       helpers    prints the runtime helpers' address ranges for PROF_HELPERS
  N: rows to print (default 40). Figures are divided by TICKS (the bench's measured ticks).
"""
import collections
import json
import re
import subprocess
import sys


def run(cmd, stdin=None):
    return subprocess.run(cmd, input=stdin, capture_output=True, text=True, check=True).stdout


def load(path, helpers=False):
    """(address, count) pairs: the instructions counted at their own address, or (helpers)
    those of the runtime helpers counted at their call site ("H" lines)."""
    rows = []
    with open(path) as f:
        for line in f:
            p = line.split()
            if (len(p) == 3) == helpers:
                rows.append((int(p[0], 16), int(p[1])))
    return rows


HELPERS = re.compile(r"compiler_builtins|__aeabi_|^mem(cpy|set|move|cmp)$|^__(mul|div|add|sub|cmp|fix|float|extend|trunc)")
LIBRARY = ("gait-core", "dxl", "libm", "micromath", "fixed")


def crate_of_symbol(name):
    """The crate of a function by its (demangled) path: for code whose inline frames are all
    core's (the outermost frame is the function it was compiled into)."""
    for prefix, crate in (("gait_core", "gait-core"), ("dxl", "dxl"), ("walker_contract", "contract"),
                          ("walker_firmware", "firmware"), ("bench", "bench tick meter"),
                          ("libm", "libm"), ("micromath", "micromath"), ("fixed", "fixed")):
        if re.match(r"(_\$LT\$)?%s(::|\.\.)" % prefix, name):
            return crate
    return "other"


def crate_of(file_name, root):
    """The project crate or maths crate a source file belongs to, or None (core, alloc,
    compiler_builtins, heapless…: their inlined code counts for the frame that called it)."""
    if file_name.startswith(root + "/"):
        rel = file_name[len(root) + 1:]
        for crate in ("gait-core", "dxl", "contract"):
            if rel.startswith(crate + "/"):
                return crate
        if rel == "src/bin/bench.rs":
            return "bench tick meter"
        if rel.startswith("src/"):
            return "firmware"
        return None
    for crate in ("libm", "micromath", "fixed"):
        if re.search(r"/%s-[0-9][^/]*/" % crate, file_name):
            return crate
    return None


def symbols(elf):
    syms = []
    for line in run(["llvm-nm", "-C", "-S", "--defined-only", elf]).splitlines():
        p = line.split(" ", 3)
        if len(p) == 4 and p[2] in "tTwW":
            syms.append((int(p[0], 16) & ~1, int(p[1], 16), p[3]))
    syms.sort()
    return syms


def frames(elf, addrs):
    text = "\n".join(hex(a) for a in addrs) + "\n"
    out = run(["llvm-symbolizer", "--output-style=JSON", "-e", elf], text).splitlines()
    return [json.loads(o).get("Symbol", []) for o in out]


def where(f):
    return "%s:%s" % (f["FileName"].split("/")[-1], f["Line"])


def main():
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    elf, counts_path, ticks, mode = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
    top = int(sys.argv[5]) if len(sys.argv) > 5 else 40
    if mode == "helpers":
        print(",".join("%x-%x" % (a, a + n) for a, n, name in symbols(elf)
                       if n > 0 and HELPERS.search(name)))
        return
    counts = load(counts_path)
    total = sum(c for _, c in counts)
    agg = collections.Counter()
    if mode == "crates":
        import os
        root = os.getcwd()
        helper_counts = load(counts_path, helpers=True)
        total += sum(c for _, c in helper_counts)
        rows = counts + helper_counts
        for (a, c), fr in zip(rows, frames(elf, [a for a, _ in rows])):
            home = next((f for f in fr if crate_of(f["FileName"], root)), None)
            owner = crate_of(home["FileName"], root) if home else None
            owner = owner or crate_of_symbol(fr[-1]["FunctionName"] if fr else "")
            if owner == "dxl":
                # The master driver's transaction logic apart from the codec it calls.
                master = home is not None and home["FileName"].endswith("/dxl/src/master.rs")
                owner = "dxl master" if master else "dxl codec"
            agg[owner] += c
        library = sum(c for k, c in agg.items() if k in LIBRARY or k.startswith("dxl "))
        master = agg["dxl master"]
        print("library calls (gait-core, dxl, libm, micromath, fixed): %.1f per tick" % (library / ticks))
        print("the loop (firmware, contract, bench tick meter, other): %.1f per tick"
              % ((total - library) / ticks))
        print("the loop with the dxl master's transactions: %.1f per tick"
              % ((total - library + master) / ticks))
    elif mode == "functions":
        import bisect
        syms = symbols(elf)
        starts = [s[0] for s in syms]
        for a, c in counts:
            i = bisect.bisect_right(starts, a) - 1
            ok = i >= 0 and a < syms[i][0] + max(syms[i][1], 2)
            agg[syms[i][2] if ok else "?%x" % a] += c
    elif mode in ("lines", "stack"):
        for (a, c), fr in zip(counts, frames(elf, [a for a, _ in counts])):
            if not fr:
                agg["?"] += c
            elif mode == "lines":
                agg["%s (%s)" % (where(fr[0]), fr[0]["FunctionName"][:60])] += c
            else:
                agg[" < ".join(where(f) for f in fr[:4])] += c
    elif mode == "calls":
        pattern = re.compile(sys.argv[6] if len(sys.argv) > 6 else "memcpy|memclr|memset|memmove")
        by_addr = dict(counts)
        sites = []
        caller = ""
        for line in run(["llvm-objdump", "-d", "--no-show-raw-insn", elf]).splitlines():
            h = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
            if h:
                caller = h.group(1)
                continue
            # Calls from inside the runtime's own helpers (memcpy's tail calls) are not sites.
            if re.search("compiler_builtins|aeabi", caller):
                continue
            m = re.match(r"\s*([0-9a-f]+):\s+(bl|b\.w|blx)\s+0x[0-9a-f]+ <(.*)>", line)
            if m and pattern.search(m.group(3)) and by_addr.get(int(m.group(1), 16)):
                a = int(m.group(1), 16)
                sites.append((a, m.group(3)))
        for (a, callee), fr in zip(sites, frames(elf, [a for a, _ in sites])):
            key = "%s <- %s" % (callee[:40], " < ".join(where(f) for f in fr[:4]) or "?")
            agg[key] += by_addr[a]
        total = None
    else:
        sys.exit(__doc__)
    if total is not None:
        print("counted %d instructions: %.1f per tick" % (total, total / ticks))
    for key, c in agg.most_common(top):
        share = "" if total is None else " %5.1f%%" % (100.0 * c / total)
        print("%9.1f%s  %s" % (c / ticks, share, key))


if __name__ == "__main__":
    main()

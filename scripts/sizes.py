#!/usr/bin/env python3
"""Flash and static RAM of firmware ELFs, read from their section headers (issue 14).

Usage: python3 scripts/sizes.py [--limit FLASH_KIB:RAM_KIB] ELF [[--limit ...] ELF ...]

A `--limit` applies to the ELF that follows it (the FPU-less Cortex-M3 board builds get
`--limit 112:16` in scripts/test.sh). Prints one row per ELF and exits 1 when an ELF exceeds
its limit (2 on a file that is not a 32-bit little-endian ELF).

Flash = every allocated section with contents (SHT_PROGBITS with SHF_ALLOC: the vector
table, .text, .rodata and the load image of .data); static RAM = every allocated section at
an address at or above 0x2000_0000 (.data, .bss, .uninit; the stack comes on top). The
numbers are the ones `readelf -S` shows, computed here without binutils or llvm-tools so
that the check runs on a fresh machine with only python3 (README setup).
"""

import struct
import sys

SHT_PROGBITS = 1
SHF_ALLOC = 0x2
RAM_BASE = 0x2000_0000


def sections(path):
    """(name, type, flags, addr, size) of every section of a 32-bit little-endian ELF."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF" or data[4] != 1 or data[5] != 1:
        raise ValueError(f"{path}: not a 32-bit little-endian ELF")
    shoff, = struct.unpack_from("<I", data, 0x20)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x2E)
    raw = [struct.unpack_from("<IIIIIIIIII", data, shoff + i * shentsize) for i in range(shnum)]
    str_off = raw[shstrndx][4]

    def name(off):
        end = data.index(b"\0", str_off + off)
        return data[str_off + off:end].decode()

    return [(name(s[0]), s[1], s[2], s[3], s[5]) for s in raw]


def sizes(path):
    """(flash, static RAM) bytes of an ELF."""
    flash = ram = 0
    for _name, typ, flags, addr, size in sections(path):
        if not flags & SHF_ALLOC:
            continue
        if typ == SHT_PROGBITS:
            flash += size
        if addr >= RAM_BASE:
            ram += size
    return flash, ram


def main(argv):
    limit = None
    rows = []
    args = iter(argv)
    for a in args:
        if a == "--limit":
            f_kib, r_kib = next(args).split(":")
            limit = (int(f_kib) * 1024, int(r_kib) * 1024)
            continue
        rows.append((a, limit))
        limit = None
    if not rows:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    failed = False
    print(f"{'ELF':<60} {'flash B':>9} {'KiB':>7} {'static RAM B':>13} {'KiB':>6}  limit")
    for path, lim in rows:
        try:
            flash, ram = sizes(path)
        except (OSError, ValueError) as e:
            print(f"sizes.py: {e}", file=sys.stderr)
            return 2
        verdict = ""
        if lim is not None:
            over = [w for w, v, m in (("flash", flash, lim[0]), ("RAM", ram, lim[1])) if v > m]
            verdict = f"≤ {lim[0] // 1024} KiB flash, ≤ {lim[1] // 1024} KiB RAM: "
            verdict += "OVER (" + ", ".join(over) + ")" if over else "ok"
            failed |= bool(over)
        print(f"{path:<60} {flash:>9,} {flash / 1024:>7.1f} {ram:>13,} {ram / 1024:>6.1f}  {verdict}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
"""Compare two BENCH_DEM_DUMP files (raw float64 [n, 9]: x, v, omega per ball).

Usage: compare_dumps.py A B
Prints, per field, the largest difference relative to the field's largest magnitude in A,
and the number of bit-identical values. Two builds of the engine that differ only by
rounding (an algebraically equal rewrite) should agree to a small multiple of 1e-16 in x
over a short held window (the packing is at equilibrium, so errors grow slowly).
"""
import struct
import sys


def load(path):
    with open(path, "rb") as f:
        data = f.read()
    return struct.unpack("<%dd" % (len(data) // 8), data)


def main():
    a, b = load(sys.argv[1]), load(sys.argv[2])
    if len(a) != len(b) or len(a) % 9:
        sys.exit("compare_dumps: sizes differ or are not [n, 9]")
    n = len(a) // 9
    same = sum(1 for p, q in zip(a, b) if p == q)
    for name, off in (("x", 0), ("v", 3), ("w", 6)):
        sa = [a[9 * i + off + k] for i in range(n) for k in range(3)]
        sb = [b[9 * i + off + k] for i in range(n) for k in range(3)]
        scale = max(abs(p) for p in sa) or 1.0
        diff = max(abs(p - q) for p, q in zip(sa, sb))
        print("%s: max |diff| / max |%s| = %.3e (scale %.3e)" % (name, name, diff / scale, scale))
    print("bit-identical values: %d of %d" % (same, len(a)))


if __name__ == "__main__":
    main()

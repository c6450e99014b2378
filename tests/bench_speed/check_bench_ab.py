#!/usr/bin/python3
"""ctest bench_dem_ab: bench_dem's in-process A/B of two pass kernels (BENCH_DEM_AB, bench/dem/bench_dem.cpp).

Invariants: every kernel gives the same bits, so an A/B run of 40 steps (scalar and auto in
blocks of 5) ends with the hash of a plain 40-step run; its "ab" line names both kernels, the
block, the steps left out, the pairs of blocks, a positive ratio (A's pair-phase time over B's),
a standard error and both times per step (also with blocks of 4 and 2 steps left out). A bad
kernel name, too few steps for two pairs of blocks, a block below 2 and a skip not below the
block stop the run with a non-zero exit and a message naming the variable or value.
Usage: check_bench_ab.py REPO_ROOT   (env DEMFDM_BUILD: the build folder holding bin/bench_dem)
"""
import os
import re
import subprocess
import sys

root = sys.argv[1]
bench = os.path.join(os.environ.get("DEMFDM_BUILD", os.path.join(root, "build")), "bin", "bench_dem")
packing = os.path.join(root, "bench", "dem", "data", "bench_packing_25835.txt")
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)
    return cond


def run(env, steps):
    e = dict(os.environ, BENCH_DEM_HASH="1", **env)
    for k in ("BENCH_DEM_AB", "BENCH_DEM_AB_BLOCK", "BENCH_DEM_KERNEL"):
        if k not in env:
            e.pop(k, None)
    p = subprocess.run([bench, packing, "linear", "1", str(steps)], capture_output=True, text=True, env=e, timeout=200)
    print("$ %s %s linear 1 %d" % (" ".join("%s=%s" % kv for kv in env.items()), bench, steps))
    print(p.stdout + p.stderr)
    return p


def digest(p):
    m = re.search(r"^hash linear threads 1 steps (\d+): ([0-9a-f]{16})", p.stderr, re.M)
    return m.group(2) if m else None


plain = run({}, 40)
check(plain.returncode == 0, "plain run: exit 0")
ab = run({"BENCH_DEM_AB": "scalar,auto", "BENCH_DEM_AB_BLOCK": "5"}, 40)
check(ab.returncode == 0, "A/B run: exit 0")
check(digest(plain) is not None and digest(plain) == digest(ab), "A/B run ends with the plain run's hash")
LINE = (r"^ab kernel_a=(\w+) kernel_b=(\w+) block=(\d+) skip=(\d+) pairs=(\d+) ratio_a_over_b=([0-9.]+) "
        r"se=([0-9.]+) a_ms=([0-9.]+) b_ms=([0-9.]+)$")


def ab_line(p, what, a, b, block, skip, pairs):
    m = re.search(LINE, p.stderr, re.M)
    if check(m is not None, what + ": ab line"):
        check(m.group(1) == a and m.group(2) == b, what + ": ab line names both kernels")
        check(m.group(3) == block and m.group(4) == skip and m.group(5) == pairs, what + ": block, skip, pairs")
        check(float(m.group(6)) > 0 and float(m.group(7)) >= 0, what + ": ratio > 0, se >= 0")
        check(float(m.group(8)) > 0 and float(m.group(9)) > 0, what + ": both times per step > 0")


ab_line(ab, "block 5", "scalar", "auto", "5", "1", "4")
ab2 = run({"BENCH_DEM_AB": "auto,scalar", "BENCH_DEM_AB_BLOCK": "4", "BENCH_DEM_AB_SKIP": "2"}, 40)
check(ab2.returncode == 0 and digest(ab2) == digest(plain), "A/B run with a skip of 2: exit 0, the plain run's hash")
ab_line(ab2, "block 4, skip 2", "auto", "scalar", "4", "2", "5")
bad = run({"BENCH_DEM_AB": "fast,auto"}, 40)
check(bad.returncode != 0 and "BENCH_DEM_AB" in bad.stderr and "'fast'" in bad.stderr, "bad kernel name: error naming it")
short = run({"BENCH_DEM_AB": "scalar,auto"}, 30)
check(short.returncode != 0 and "BENCH_DEM_AB" in short.stderr and "at least 40 steps" in short.stderr,
      "too few steps: error giving the least count")
blk = run({"BENCH_DEM_AB": "scalar,auto", "BENCH_DEM_AB_BLOCK": "1"}, 40)
check(blk.returncode != 0 and "BENCH_DEM_AB_BLOCK" in blk.stderr, "block below 2: error naming BENCH_DEM_AB_BLOCK")
skp = run({"BENCH_DEM_AB": "scalar,auto", "BENCH_DEM_AB_BLOCK": "5", "BENCH_DEM_AB_SKIP": "5"}, 40)
check(skp.returncode != 0 and "BENCH_DEM_AB_SKIP" in skp.stderr, "skip not below the block: error naming it")


if fails:
    print("FAILED (%d):" % len(fails))
    for f in fails:
        print("  " + f)
    sys.exit(1)
print("bench_dem_ab: OK")

#!/usr/bin/env python3
"""Newton's ghost coefficient in weak form, with the same machine load on both sides
(docs/scaling.md, session 28; the projection's NEWTON_GHOST_COEFF in project_scaling.py).

Each pair runs, in alternated order:
  - `mpirun -n 2 bench_dist PACKING linear STEPS weak` with BENCH_DIST_NEWTON=1 and
    BENCH_DIST_AXIS=AXIS: two ranks, one copy of the packing each, cut across AXIS;
  - two 1-rank `bench_dist ... strong` runs at once, one pinned to each of the first two cores
    (`taskset -c 0` / `-c 1`, mpirun --bind-to none: two separate mpirun -n 1 would otherwise
    both bind to core 0).
The ratio of a pair is the 2-rank figure (mean over its ranks) over the mean of the two 1-rank
runs; the coefficient c of forces = F1/P (1 + c g) is (ratio - 1) / g, g the ghosts per owned
ball the 2-rank run reports. Prints mean (standard error) and median per phase; every run's CSV
line is appended to --out.

Needs 2 free cores; a machine that runs anything else meanwhile moves the figures.
Usage: ghost_coeff.py [--build DIR] [--pairs N] [--axis x|y|z] [--steps N] [--out CSV]
"""
import argparse
import csv
import io
import os
import statistics as st
import subprocess
import sys

from bench_env import bench_dist, mpi_env

HERE = os.path.dirname(os.path.abspath(__file__))
PHASES = ("forces_ms", "pair_ms", "rebuild_ms", "motion_ms")


def run(cmds, env):
    """Start every command at once; the last CSV row of each (header + row) as a dict."""
    procs = [subprocess.Popen(c, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in cmds]
    rows = []
    for c, p in zip(cmds, procs):
        out, err = p.communicate()
        if p.returncode != 0:
            sys.exit(f"ghost_coeff.py: {' '.join(c)} exited {p.returncode}: {err.strip()[-400:]}")
        lines = [l for l in out.splitlines() if l.strip()]
        rows.append(next(csv.DictReader(io.StringIO(lines[-2] + "\n" + lines[-1]))))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.environ.get("DEMFDM_BUILD", os.path.join(HERE, "..", "..", "build")))
    ap.add_argument("--pairs", type=int, default=40)
    ap.add_argument("--axis", choices=("x", "y", "z"), default="z")
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--out", default=None, help="append every run's CSV line here (with pair and role)")
    args = ap.parse_args()
    exe = bench_dist(args.build, "ghost_coeff.py")
    pk = os.path.join(HERE, "data", "bench_packing_25835.txt")
    env = mpi_env(BENCH_DIST_NEWTON="1", OMP_NUM_THREADS="1")
    base = [exe, pk, "linear", str(args.steps)]
    weak_cmd = ["mpirun", "-n", "2"] + base + ["weak"]
    ref_cmds = [["taskset", "-c", str(k), "mpirun", "--bind-to", "none", "-n", "1"] + base + ["strong"] for k in (0, 1)]
    ratios = {k: [] for k in PHASES}
    g = None
    out = open(args.out, "a", newline="") if args.out else None
    for i in range(1, args.pairs + 1):
        order = ("weak", "ref") if i % 2 else ("ref", "weak")
        got = {}
        for role in order:
            if role == "weak":
                got[role] = run([weak_cmd], dict(env, BENCH_DIST_AXIS=args.axis))
            else:
                got[role] = run(ref_cmds, env)
        w = got["weak"][0]
        g = float(w["ghosts_per_owned"])
        for k in PHASES:
            ratios[k].append(float(w[k]) / st.mean(float(r[k]) for r in got["ref"]))
        if out:
            for role in order:
                for r in got[role]:
                    out.write(f"{i},{role}," + ",".join(r.values()) + "\n")
            out.flush()
        print(f"pair {i}: forces {ratios['forces_ms'][-1]:.4f}", file=sys.stderr)
    n = args.pairs
    print(f"# {n} pairs, 2 ranks weak across {args.axis} ({g:.4f} ghosts per owned ball) against two 1-rank runs at once")
    print("phase,ratio_mean,ratio_se,ratio_median,coeff,coeff_se")
    for k in PHASES:
        v = ratios[k]
        m = st.mean(v)
        se = st.stdev(v) / n ** 0.5 if n > 1 else float("nan")
        print(f"{k},{m:.4f},{se:.4f},{st.median(v):.4f},{(m - 1) / g:.3f},{se / g:.3f}")


if __name__ == "__main__":
    main()

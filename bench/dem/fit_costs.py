#!/usr/bin/env python3
"""The balancing's cost model (ContactCost in dem_node/dist, docs/scaling.md, session 29), fitted
to a run's own state on this machine.

Runs `mpirun -n 2 bench_dist --run CHECKPOINT STEPS BALANCE` with newton on and order-free sums
(BENCH_DIST_PER_RANK=1: each rank's phase times and counts) under five cuts, ROUNDS times each:
geometric RCB; slabs across x, y and z; RCB balanced by the model's costs. Each rank's phase
times against its counts, least squares through the origin over every rank-run:
  pair pass   = bonded pairs x b + pairs apart x a (+ unbonded pairs that touch x t, when the
                state has enough of them: at least 5 % of its pairs)
  facet pass  = facet contacts x f
  motion      = owned balls x m
  rebuild     = listed pairs x r
  rest of the forces phase = owned balls x o
and prints them in ns with each fit's rms relative residual, then the integer costs
(BENCH_DIST_COST and the scene key dem.balance_costs, in the order ball, bonded end, touching
end, apart end, facet, plane) that they give:
the ball m + o, a pair's end (its pass + r) / 2, the plane and footing contacts a bonded pair's
cost (not fitted). Every run's JSON record is appended to --out.

Needs 2 free cores; a machine that runs anything else meanwhile moves the figures.
Usage: fit_costs.py CHECKPOINT [--build DIR] [--rounds N] [--steps N] [--out JSONL]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

from bench_env import bench_dist, mpi_env

HERE = os.path.dirname(os.path.abspath(__file__))
CUTS = {
    "rcb": ({}, "0"),
    "slabs_x": ({"BENCH_DIST_DECOMP": "slabs", "BENCH_DIST_AXIS": "x"}, "0"),
    "slabs_y": ({"BENCH_DIST_DECOMP": "slabs", "BENCH_DIST_AXIS": "y"}, "0"),
    "slabs_z": ({"BENCH_DIST_DECOMP": "slabs", "BENCH_DIST_AXIS": "z"}, "0"),
    "rcb_balanced": ({}, "1"),
}


def run(exe, ck, steps, env, balance):
    """One 2-rank run: {rank: {count or phase: value}}."""
    out = subprocess.run(["mpirun", "-n", "2", exe, "--run", ck, str(steps), balance], env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"fit_costs.py: bench_dist exited {out.returncode}: {out.stderr.strip()[-400:]}")
    ranks = {}
    for ln in out.stdout.splitlines():
        if ln.startswith("rank,"):
            p = ln.split(",")
            d = ranks.setdefault(int(p[1]), {})
            for i in range(2, len(p) - 1, 2):
                d[p[i]] = float(p[i + 1])
    if sorted(ranks) != [0, 1]:
        sys.exit("fit_costs.py: bench_dist printed no per-rank lines")
    return ranks


def fit(rows, target, cols):
    """Least squares through the origin: target = sum(cols x costs); costs [ms per count], the rms
    relative residual."""
    x = np.array([[r[c] for c in cols] for r in rows])
    y = np.array([target(r) for r in rows])
    cost = np.linalg.lstsq(x, y, rcond=None)[0]
    return cost, float(np.sqrt(np.mean(((y - x @ cost) / y) ** 2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", help="a run's checkpoint folder (bench_dist --run)")
    ap.add_argument("--build", default=os.environ.get("DEMFDM_BUILD", os.path.join(HERE, "..", "..", "build")))
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--out", default=None, help="append every run's JSON record here")
    args = ap.parse_args()
    exe = bench_dist(args.build, "fit_costs.py")
    env = mpi_env(BENCH_DIST_NEWTON="1", BENCH_DIST_ORDER_FREE="1", BENCH_DIST_PER_RANK="1", OMP_NUM_THREADS="1")
    rows = []
    for rnd in range(args.rounds):
        for name, (cut_env, balance) in CUTS.items():
            ranks = run(exe, args.checkpoint, args.steps, dict(env, **cut_env), balance)
            for k, d in ranks.items():
                rows.append(dict(d, cut=name, round=rnd, rank=k))
            if args.out:
                with open(args.out, "a") as f:
                    f.write(json.dumps({"round": rnd, "cut": name, "ranks": ranks}) + "\n")
            print(f"round {rnd} {name}: compute {ranks[0]['motion_ms'] + ranks[0]['forces_ms']:.3f} / "
                  f"{ranks[1]['motion_ms'] + ranks[1]['forces_ms']:.3f} ms", flush=True)
    pairs = sum(r["pairs"] for r in rows)
    touching = sum(r["unbonded_touching"] for r in rows) >= 0.05 * pairs
    pair_cols = ["bonded", "unbonded_apart"] + (["unbonded_touching"] if touching else [])
    pc, pr = fit(rows, lambda r: r["pair_ms"], pair_cols)
    fc, fr = fit(rows, lambda r: r["facet_ms"], ["facet_contacts"]) if any(r["facet_contacts"] for r in rows) else ([0.0], 0.0)
    mc, mr = fit(rows, lambda r: r["motion_ms"], ["owned"])
    rc, rr = fit(rows, lambda r: r["rebuild_ms"], ["pairs"])
    oc, orr = fit(rows, lambda r: r["forces_ms"] - r["pair_ms"] - r["facet_ms"] - r["rebuild_ms"], ["owned"])
    ns = 1e6  # ms -> ns
    print(f"# {len(rows)} rank-runs, {args.steps} steps each; costs [ns per step] (rms relative residual)")
    for what, c, res in (("pair pass", dict(zip(pair_cols, pc)), pr), ("facet pass", {"facet_contacts": fc[0]}, fr),
                         ("motion", {"owned": mc[0]}, mr), ("rebuild", {"pairs": rc[0]}, rr),
                         ("rest of forces", {"owned": oc[0]}, orr)):
        print(f"{what}: " + ", ".join(f"{k} {v * ns:.1f}" for k, v in c.items()) + f" ({res:.3f})")
    bonded, apart = pc[0] * ns, pc[1] * ns
    touch = pc[2] * ns if touching else bonded
    r = rc[0] * ns
    costs = [max(1, round((mc[0] + oc[0]) * ns)), round((bonded + r) / 2), round((touch + r) / 2),
             round((apart + r) / 2), round(fc[0] * ns), round(bonded + r)]
    costs = [max(0, c) for c in costs]
    print("BENCH_DIST_COST=" + ",".join(str(c) for c in costs) +
          "  (ball, bonded end, touching end, apart end, facet, plane)" +
          ("" if touching else "; touching as bonded: too few unbonded pairs that touch"))
    print("scene: [dem] balance_costs = [" + ", ".join(str(c) for c in costs) + "]")


if __name__ == "__main__":
    main()

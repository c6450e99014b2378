#!/usr/bin/python3
"""ctest bench_project_scaling: bench/dem/project_scaling.py (docs/scaling.md), both workloads,
both networks, against invariants of its cost model:
- one rank: efficiency 1.000, no communication (exchange, forward, reduce, walls all 0);
- every part >= 0 and the total their sum (to the printed rounding);
- more ranks never cost less in any part than 2 ranks, and the efficiency never rises with the
  rank count within a design (the walls' sums may fall by up to 2 %: Open MPI changes its
  allreduce algorithm with the rank count, and Rabenseifner's at 256 ranks can undercut
  recursive doubling at 64 for the same vector);
- allreduce_us against the hand-worked cost of Open MPI 4.1.4's choice at 64 ranks: recursive
  doubling below 256 KiB, Rabenseifner from there;
- the footing workload (one rebuild per 699 steps) pays less exchange per step than the bench
  (one per 23) at every rank count above 1, and its walls' sums gathered on rank 0 ("today") grow
  faster with the rank count than its order-free ones;
- Ethernet is never faster than InfiniBand;
- a faster core (--compute-scale 0.5) halves the compute of every row and raises no efficiency
  above 1, and none above its own at scale 1;
- an even time per weight (--time-per-weight 0) raises the newton designs above 1 rank and
  leaves every other row as it was; the "newton at 64 ranks: E +- S" line matches the table,
  with 0 < S < 0.05;
- the ghosts per owned ball of a cubic brick of 25,835 balls at the bench's density and halo:
  ((a + 2 h)^3 - a^3) / a^3 from the script's own figures, 0.469.
Usage: check_project_scaling.py REPO_ROOT
"""
import csv
import importlib.util
import io
import re
import subprocess
import sys

root = sys.argv[1]
script = root + "/bench/dem/project_scaling.py"
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


def run(*args):
    out = subprocess.run([sys.executable, script, "--csv", *args], capture_output=True, text=True, timeout=60)
    check(out.returncode == 0, "project_scaling.py %s: exit %d: %s" % (" ".join(args), out.returncode, out.stderr))
    head, body = out.stdout.split("\n", 1)
    rows = list(csv.DictReader(io.StringIO(body)))
    return head, rows


parts = ("compute_ms", "exchange_ms", "forward_ms", "reduce_ms", "walls_ms")
tables = {}
for wl in ("bench", "footing"):
    for net in ("ib", "ethernet"):
        head, rows = run("--workload", wl, "--network", net)
        tables[(wl, net)] = rows
        check(len(rows) == 4 * 6, "%s %s: %d rows" % (wl, net, len(rows)))
        if wl == "bench":
            g = float(re.search(r"ghosts per owned ball in a cubic brick: ([0-9.]+)", head).group(1))
            check(abs(g - 0.469) < 0.0005, "bench: ghosts per owned ball %.3f, expected 0.469" % g)
        for design in sorted({r["design"] for r in rows}):
            rs = sorted((r for r in rows if r["design"] == design), key=lambda r: int(r["ranks"]))
            one = rs[0]
            check(one["ranks"] == "1" and one["efficiency"] == "1.000", "%s %s %s: one rank %s" % (wl, net, design, one))
            check(all(float(one[k]) == 0.0 for k in parts[1:]), "%s %s %s: one rank communicates" % (wl, net, design))
            for r in rs:
                vals = [float(r[k]) for k in parts]
                check(min(vals) >= 0.0, "%s %s %s %s: a negative part" % (wl, net, design, r["ranks"]))
                check(abs(sum(vals) - float(r["total_ms"])) <= 0.003, "%s %s %s %s: parts %.3f, total %s" %
                      (wl, net, design, r["ranks"], sum(vals), r["total_ms"]))
            for a, b in zip(rs[1:], rs[2:]):
                for k in parts:
                    slack = 0.02 * float(a[k]) if k == "walls_ms" else 0.0
                    check(float(b[k]) >= float(a[k]) - slack - 1e-9, "%s %s %s: %s falls from %s to %s ranks" %
                          (wl, net, design, k, a["ranks"], b["ranks"]))
                check(float(b["efficiency"]) <= float(a["efficiency"]), "%s %s %s: efficiency rises from %s to %s ranks" %
                      (wl, net, design, a["ranks"], b["ranks"]))


# the collective's cost model itself (InfiniBand: alpha 2 us, beta 10 GB/s = 1e4 bytes per us)
spec = importlib.util.spec_from_file_location("project_scaling", script)
ps = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ps)
ib = ps.NETWORKS["ib"]
for nbytes, want in ((8, 6 * (2.0 + 8 / 1e4)), (262143, 6 * (2.0 + 262143 / 1e4)),
                     (262144, 2 * 6 * 2.0 + 2 * 63 / 64 * 262144 / 1e4), (1 << 20, 24.0 + 2 * 63 / 64 * (1 << 20) / 1e4)):
    got = ps.allreduce_us(64, nbytes, ib)
    check(abs(got - want) < 1e-9 * want, "allreduce_us(64, %d): %.6f us, expected %.6f" % (nbytes, got, want))
check(ps.allreduce_us(1, 1 << 20, ib) == 0.0, "allreduce_us: one rank costs something")


def cell(wl, net, design, ranks, key):
    return float(next(r for r in tables[(wl, net)] if r["design"] == design and r["ranks"] == str(ranks))[key])


for P in (2, 8, 64, 256, 1024):
    check(cell("footing", "ib", "today", P, "exchange_ms") < cell("bench", "ib", "today", P, "exchange_ms"),
          "footing: exchange not below the bench's at %d ranks" % P)
    for wl in ("bench", "footing"):
        for design in ("today", "order-free", "newton", "next"):
            check(cell(wl, "ethernet", design, P, "total_ms") >= cell(wl, "ib", design, P, "total_ms"),
                  "%s %s: Ethernet faster than InfiniBand at %d ranks" % (wl, design, P))
_, fast = run("--workload", "footing", "--network", "ib", "--compute-scale", "0.5")
for r, r1 in zip(fast, tables[("footing", "ib")]):
    check(abs(float(r["compute_ms"]) - 0.5 * float(r1["compute_ms"])) <= 0.002,
          "compute-scale 0.5: %s %s compute %s against %s" % (r["design"], r["ranks"], r["compute_ms"], r1["compute_ms"]))
    check(float(r["efficiency"]) <= float(r1["efficiency"]) and float(r["efficiency"]) <= 1.0,
          "compute-scale 0.5: %s %s efficiency %s against %s" % (r["design"], r["ranks"], r["efficiency"], r1["efficiency"]))
# the time per weight only moves the newton designs, and an even one (0) raises them
_, even = run("--workload", "footing", "--network", "ib", "--time-per-weight", "0")
for r, r1 in zip(even, tables[("footing", "ib")]):
    if r["design"] in ("newton", "next") and r["ranks"] != "1":
        check(float(r["efficiency"]) > float(r1["efficiency"]),
              "time-per-weight 0: %s %s efficiency %s not above %s" % (r["design"], r["ranks"], r["efficiency"], r1["efficiency"]))
    else:
        check(r == r1, "time-per-weight 0 moved %s %s" % (r["design"], r["ranks"]))
# the standard error line: newton at 64 ranks as in the table, a positive error
out = subprocess.run([sys.executable, script, "--workload", "footing"], capture_output=True, text=True, timeout=60).stdout
mm = re.search(r"newton at 64 ranks: ([0-9.]+) \+- ([0-9.]+)", out)
check(mm is not None, "no 'newton at 64 ranks: E +- S' line")
if mm:
    check(abs(float(mm.group(1)) - cell("footing", "ib", "newton", 64, "efficiency")) <= 0.0005,
          "newton at 64 ranks %s, the table %s" % (mm.group(1), cell("footing", "ib", "newton", 64, "efficiency")))
    check(0.0 < float(mm.group(2)) < 0.05, "newton's standard error %s" % mm.group(2))
grow = lambda d: cell("footing", "ib", d, 1024, "walls_ms") / cell("footing", "ib", d, 64, "walls_ms")
check(grow("today") > grow("order-free"), "footing: the gathered walls' sums grow no faster than the order-free ones")
print("project_scaling.py: %d tables checked; footing at 64 ranks, InfiniBand: today %.3f, order-free %.3f, newton %.3f" %
      (len(tables), cell("footing", "ib", "today", 64, "efficiency"), cell("footing", "ib", "order-free", 64, "efficiency"),
       cell("footing", "ib", "newton", 64, "efficiency")))
for f in fails:
    print("FAIL:", f)
sys.exit(1 if fails else 0)

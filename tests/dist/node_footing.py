#!/usr/bin/python3
"""The reduced coupled footing (scenes/footing_small.toml, all six stages) with the DEM on MPI
ranks, through launch/run as a user runs it (issue 17 items 3 and 4): dem.ranks = 1 (one process,
no MPI), 2 and 3 (3 on 2 cores: oversubscribed; cuts balanced by contacts), and 2 ranks of 2
threads each (cuts balanced by measured time), with frames inside
the stages every 700 steps (the ranks' parts assembled, then stepping on). Every CSV file of
the run folders (histories of both nodes and of the coordinator, stress profiles, specimen stages)
must be the same bytes as the one-process run's, and every dataset of dem.h5 and fdm.h5 the same
bits; the interface balance holds to round-off; the ranked runs did step on ranks (the node's log
names the ranks' communication in the stages' values); a branch on 3 ranks from the 3-rank run's
gravity checkpoint repeats the one-process penetration byte for byte; the DEM-only footing in a
box of five planes (scenes/accuracy_footing_box.toml, reduced) gives one process's bytes on 2 ranks;
and dem.newton = true on 2 ranks repeats itself and stays within round-off through gravity.

Usage: node_footing.py SOURCE_DIR BUILD_DIR WORK_DIR
"""
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np

src, build, work = sys.argv[1:4]
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)

# (name, ranks, threads, more overrides): 3 ranks balance their cuts by contacts every 2nd
# rebuild (with session 28's weights through dem.balance_costs), 2 x 2 by measured time every 3rd
# (the cuts then differ from run to run, the bits not).
runs = [("ranks1", 1, 1, []), ("ranks2", 2, 1, []),
        ("ranks3", 3, 1, ["dem.balance_every=2", "dem.balance_costs=[1,1,1,1,5,1]"]),
        ("ranks2_threads2", 2, 2, ["dem.balance_every=3", "dem.balance_weight=time", "dem.decomposition=slabs"])]
env = dict(os.environ, DEMFDM_BUILD=build)
for name, ranks, threads, more in runs:
    out = os.path.join(work, name)
    sets = []
    for m in more:
        sets += ["--set", m]
    p = subprocess.run(["/bin/bash", os.path.join(src, "launch/run"), os.path.join(src, "scenes/footing_small.toml"),
                        "--no-build", "--run-dir", out, "--set", "dem.ranks=%d" % ranks, "--set", "run.threads=%d" % threads,
                        "--set", "output.traffic_log=false", "--set", "dem.output.frame_every=700"] + sets,
                       env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        print(p.stdout[-4000:])
        sys.exit("FAIL: the run with %d ranks x %d threads ended with code %d" % (ranks, threads, p.returncode))
    print("run %s: %d ranks x %d threads, code 0" % (name, ranks, threads))

failures = []
ref = os.path.join(work, "ranks1")
csvs = sorted(n for n in os.listdir(ref) if n.endswith(".csv"))
needed = {"dem_history.csv", "fdm_history.csv", "history_4_gravity.csv", "history_5_penetrate.csv",
          "specimen_stages.csv", "dem_profile_penetrate.csv"}
if not needed <= set(csvs):
    failures.append("the reference run lacks %s" % sorted(needed - set(csvs)))


def datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, np.asarray(o[()])) if isinstance(o, h5py.Dataset) else None)
    return out


def stage_values(log):
    """Each stage's end values in a dem.log, without the timings and memory: {stage: {key: value}}."""
    out = {}
    for m in re.finditer(r"stage (\d+) '([^']+)' ends after step \d+; values: (.*)", log):
        vals = {}
        for kv in m.group(3).split():
            k, _, v = kv.partition("=")
            if not (k.startswith("effect_s.") or k.startswith("peak_rss") or k == "cpu_s"):
                vals[k] = float(v)
        out[m.group(2)] = vals
    return out


ref_h5 = {n: datasets(os.path.join(ref, n)) for n in ("dem.h5", "fdm.h5")}
ref_values = stage_values(open(os.path.join(ref, "dem.log")).read())
for name, ranks, threads, more in runs[1:]:
    d = os.path.join(work, name)
    for n in csvs:
        a = open(os.path.join(ref, n), "rb").read()
        p = os.path.join(d, n)
        b = open(p, "rb").read() if os.path.exists(p) else b""
        if a != b:
            al, bl = a.decode().split("\n"), b.decode().split("\n")
            i = next((k for k in range(min(len(al), len(bl))) if al[k] != bl[k]), min(len(al), len(bl)))
            failures.append("%s: %s differs from one process's at line %d" % (name, n, i + 1))
    for n, want in ref_h5.items():
        got = datasets(os.path.join(d, n))
        if set(got) != set(want):
            failures.append("%s: %s has other datasets" % (name, n))
            continue
        bad = [k for k in want if want[k].tobytes() != got[k].tobytes() or want[k].dtype != got[k].dtype]
        if bad:
            failures.append("%s: %s datasets differ: %s" % (name, n, bad[:5]))
    log = open(os.path.join(d, "dem.log")).read()
    # Every stage's end values are one process's: the same bits, the energies to round-off. The
    # dissipated energies are the ranks' sums in rank order (docs/scaling.md), and a stage's
    # dissipation is the difference of the run's cumulative totals: in the gravity stage, which
    # dissipates 4.4e-13 J, that round-off is 2e-5 of it (the balance error differs by 5e-6;
    # as before session 31). A stage's energy taken from a stale World misses by far more
    # (session 31's first coupled set-up on the ranks: a balance error of -0.56, one process -0.0018).
    got_values = stage_values(log)
    if set(got_values) != set(ref_values):
        failures.append("%s: stages %s end, one process's %s" % (name, sorted(got_values), sorted(ref_values)))
    for stage, want in ref_values.items():
        for k, v in want.items():
            g = got_values.get(stage, {}).get(k)
            scale = max(abs(want.get(e, 0.0)) for e in ("energy_kinetic_J", "energy_strain_J",
                                                        "energy_dissipated_J", "energy_work_J"))
            tol = 1e-4 if k == "energy_balance_error" else 1e-4 * scale  # (a ratio; joules)
            ok = g is not None and (g == v or (k.startswith("energy_") and abs(g - v) <= tol))
            if not ok:
                failures.append("%s: stage '%s' ends with %s = %r, one process %r" % (name, stage, k, g, v))
    m = re.search(r"stage 5 'penetrate' ends.*effect_s\.ranks\.exchange=([0-9.e+-]+)", log)
    if not m:
        failures.append("%s: the node's log names no ranks' exchange in the penetration: it did not step on ranks" % name)
    # The ranks stay live from the replicate stage to the run's end (docs/scaling.md): no stage after
    # it loads parts from rank 0, and none assembles the World there: the stage-end checkpoints
    # (replicate, gravity) merge the parts' rows into their files (DistDem::save_state_file).
    for stage in ("4 'gravity'", "5 'penetrate'"):
        if re.search(r"stage %s ends.*effect_s\.ranks\.load=" % stage, log):
            failures.append("%s: stage %s loaded parts from rank 0" % (name, stage))
    saved = re.findall(r"dem: checkpoint (\S+): [0-9]+ balls written from the [0-9]+ ranks' parts", log)
    if "replicate-" not in " ".join(saved) or "gravity-" not in " ".join(saved):
        failures.append("%s: the replicate and gravity checkpoints were not written from the ranks' parts (%s)" % (name, saved))
    if "assembled into rank 0's World" in log:
        failures.append("%s: the World was assembled on rank 0 after the replication" % name)
    if "the block replicated on" not in log or "(the ranks stay live)" not in log:
        failures.append("%s: the node's log does not say that the ranks stay live from the replication" % name)
    summary = open(os.path.join(d, "summary.txt")).read()
    pm = re.search(r"Peak memory \(resident set\):.* dem ([0-9]+) MB \(rank 0; its other ranks at most ([0-9]+) MB each\)",
                   summary)
    if not pm or float(pm.group(1)) <= 0 or float(pm.group(2)) <= 0:
        failures.append("%s: the summary gives no peak memory of the DEM's ranks" % name)
    if more and not re.search(r"dem: [1-9][0-9]* rebalances of the ranks' cuts", log):
        failures.append("%s: the ranks did not rebalance their cuts" % name)
    print("%s: %d CSV files and %d + %d datasets compared with one process's" %
          (name, len(csvs), len(ref_h5["dem.h5"]), len(ref_h5["fdm.h5"])))

# A branch from the 3-rank run's checkpoint at the end of the gravity stage (one World's state file
# written from the ranks' parts), run on 3 ranks, which load their parts from it: its
# penetration is the one-process run's.
branch = os.path.join(work, "branch_ranks3")
p = subprocess.run(["/bin/bash", os.path.join(src, "launch/run"), os.path.join(src, "scenes/footing_small.toml"),
                    "--no-build", "--from", os.path.join(work, "ranks3", "checkpoints", "gravity-460-end"), "--run-dir",
                    branch, "--set", "dem.ranks=3", "--set", "output.traffic_log=false"],
                   env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
if p.returncode != 0:
    failures.append("the branch from the 3-rank gravity checkpoint ended with code %d\n%s" % (p.returncode, p.stdout[-3000:]))
else:
    same = 0
    for n in ("history_5_penetrate.csv", "dem_profile_penetrate.csv", "fdm_profile_penetrate.csv"):
        if open(os.path.join(ref, n), "rb").read() != open(os.path.join(branch, n), "rb").read():
            failures.append("branch_ranks3: %s differs from one process's" % n)
        else:
            same += 1
    print("branch on 3 ranks from the 3-rank gravity checkpoint: %d of 3 penetration files the same bytes" % same)
    blog = open(os.path.join(branch, "dem.log")).read()
    if "the block loaded from the checkpoint into 3 bricks" not in blog or "assembled into rank 0's World" in blog:
        failures.append("branch_ranks3: the ranks did not load their parts from the checkpoint, or rank 0 assembled the World")

# DEM only, in a box of five planes (scenes/accuracy_footing_box.toml reduced to 1,904 balls):
# 2 ranks give one process's bytes in every CSV file, with the default sums and with
# run.order_free_sums (the ranks fold their own terms; its histories differ from the default
# ones in the last bits, so at least one file must differ between the two modes).
box = {}
for mode in ("plain", "order_free"):
    for ranks in (1, 2):
        d = os.path.join(work, "box_%s_ranks%d" % (mode, ranks))
        extra = ["--set", "run.order_free_sums=true"] if mode == "order_free" else []
        p = subprocess.run(["/bin/bash", os.path.join(src, "launch/run"), os.path.join(src, "scenes/accuracy_footing_box.toml"),
                            "--no-build", "--run-dir", d, "--set", "dem.ranks=%d" % ranks, "--set",
                            "dem.specimen.replicate=[1, 1, 2]", "--set", "stage.gravity.steps=400", "--set",
                            "stage.penetrate.depth_ratio=0.03", "--set", "output.traffic_log=false"] + extra,
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if p.returncode != 0:
            failures.append("the DEM-only box (%s) on %d ranks ended with code %d\n%s" % (mode, ranks, p.returncode,
                                                                                         p.stdout[-3000:]))
        box[(mode, ranks)] = d
if all(os.path.exists(os.path.join(d, "dem_history.csv")) for d in box.values()):
    for mode in ("plain", "order_free"):
        one, two = box[(mode, 1)], box[(mode, 2)]
        names = sorted(n for n in os.listdir(one) if n.endswith(".csv"))
        bad = [n for n in names if not os.path.exists(os.path.join(two, n)) or
               open(os.path.join(one, n), "rb").read() != open(os.path.join(two, n), "rb").read()]
        print("DEM-only box of planes (%s sums) on 2 ranks: %d of %d CSV files the bytes of one process" %
              (mode, len(names) - len(bad), len(names)))
        if bad or len(names) < 5:
            failures.append("DEM-only box (%s): %s differ (of %d)" % (mode, bad, len(names)))
    differ = [n for n in names if open(os.path.join(box[("plain", 1)], n), "rb").read() !=
              open(os.path.join(box[("order_free", 1)], n), "rb").read()]
    print("order-free against default sums: %d of %d CSV files differ (%s)" % (len(differ), len(names), differ))
    if not differ:
        failures.append("run.order_free_sums changed no file: the option did not reach the measurements")

# dem.newton = true on 2 ranks (each pair across the cut computed once, its force on the other
# rank's ball sent back): not one process's bits (a ball adds its remote pairs after its local
# ones), but the same bits twice, the gravity stage within round-off grown, the elastic branch's
# stiffness to 1e-6, the interface balance at round-off, and the node names the mode. The
# gravity stage's end values: the strain energy and the facets' force to 1e-5 relative (measured
# 6e-7 and 1e-7 with the ghosts in rows of their own); the residuals of the settled specimen, the
# unbalanced ratio and the kinetic energy, are near zero, so their relative differences are
# those of the forces amplified a thousandfold (1.6e-3 and 3e-4 measured): they are held to 1e-5
# of their scale instead, the ratio as a fraction of the mean contact force (its own unit) and
# the kinetic energy as a fraction of the strain energy (measured 1.5e-6 and 6e-10). Past the first bond failures the
# penetration is another draw of this brittle 476-ball specimen (docs/scaling.md).
newton = []
for k in (1, 2):
    d = os.path.join(work, "ranks2_newton_%d" % k)
    p = subprocess.run(["/bin/bash", os.path.join(src, "launch/run"), os.path.join(src, "scenes/footing_small.toml"),
                        "--no-build", "--run-dir", d, "--set", "dem.ranks=2", "--set", "run.threads=1", "--set",
                        "output.traffic_log=false", "--set", "dem.newton=true"],
                       env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        failures.append("dem.newton on 2 ranks ended with code %d\n%s" % (p.returncode, p.stdout[-3000:]))
    newton.append(d)
if all(os.path.exists(os.path.join(d, "history_5_penetrate.csv")) for d in newton):
    same = [n for n in csvs if open(os.path.join(newton[0], n), "rb").read() == open(os.path.join(newton[1], n), "rb").read()]
    if len(same) != len(csvs):
        failures.append("dem.newton: two runs differ in %s" % sorted(set(csvs) - set(same)))
    log = open(os.path.join(newton[0], "dem.log")).read()
    if "newton on" not in log:
        failures.append("dem.newton: the node's log does not name the mode")

    def stage_values(d, stage):
        line = [l for l in open(os.path.join(d, "dem.log")) if "stage %s ends" % stage in l][0]
        return dict((k, float(v)) for k, v in re.findall(r"(\w+)=([-0-9.e+]+)", line.split("values:")[1]))

    one, two = stage_values(ref, "4 'gravity'"), stage_values(newton[0], "4 'gravity'")
    worst = max(abs(two[k] - one[k]) / abs(one[k]) for k in ("energy_strain_J", "facet_fz_N"))
    resid = max(abs(two["ratio"] - one["ratio"]),
                abs(two["energy_kinetic_J"] - one["energy_kinetic_J"]) / abs(one["energy_strain_J"]))
    k1 = re.search(r"k_e ([0-9.e+]+)", open(os.path.join(ref, "summary.txt")).read()).group(1)
    k2 = re.search(r"k_e ([0-9.e+]+)", open(os.path.join(newton[0], "summary.txt")).read()).group(1)
    hist = open(os.path.join(newton[0], "history_5_penetrate.csv")).read().split("\n")
    kk = hist[0].split(",").index("continuum.iface_imbalance")
    imb = max(abs(float(l.split(",")[kk])) for l in hist[1:] if l)
    print("dem.newton on 2 ranks: two runs the same bytes (%d files); gravity end values within %.1e of one process's "
          "(residuals %.1e of their scale); k_e %s against %s N/m; interface imbalance %.1e"
          % (len(same), worst, resid, k2, k1, imb))
    if not worst < 1e-5:
        failures.append("dem.newton: the gravity stage's end values differ by %.1e" % worst)
    if not resid < 1e-5:
        failures.append("dem.newton: the gravity stage's residuals differ by %.1e of their scale" % resid)
    if abs(float(k2) - float(k1)) > 1e-6 * float(k1):
        failures.append("dem.newton: k_e %s against %s" % (k2, k1))
    if not imb < 1e-12:
        failures.append("dem.newton: interface imbalance %.3e" % imb)

# The interface balance (continuum.iface_imbalance, docs/theory.md 6.4) at round-off in every step.
hist = open(os.path.join(work, "ranks3", "history_5_penetrate.csv")).read().split("\n")
cols = hist[0].split(",")
k = cols.index("continuum.iface_imbalance")
worst = max(abs(float(l.split(",")[k])) for l in hist[1:] if l)
print("largest interface imbalance in the penetration on 3 ranks: %.3e" % worst)
if not worst < 1e-12:
    failures.append("interface imbalance %.3e is not round-off" % worst)
rows = len(hist) - 2
if rows < 1000:
    failures.append("the penetration has only %d steps" % rows)

for f in failures:
    print("FAIL:", f)
sys.exit(1 if failures else 0)

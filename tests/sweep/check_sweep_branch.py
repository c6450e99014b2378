#!/usr/bin/python3
"""ctest sweep_branch: branching inside a sweep, with the executables of DEMFDM_BUILD. Two runs of
scenes/footing_small.toml that differ only in the penetration depth (stage.penetrate.depth_ratio
0.02 and 0.03, about 3 s each): run 1 starts from scratch, run 2 from run 1's gravity-end state
(index column branched_from, its summary says so, it has no history of the stages before the
penetration), and both report their footing result (peak_N, k_e_N_m, final_N, target_reached)
in index.csv and index.json.
Usage: check_sweep_branch.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = sys.argv[1]
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


tmp = tempfile.mkdtemp(prefix="demfdm-sweep-branch-")
try:
    into = os.path.join(tmp, "sw")
    r = subprocess.run([os.path.join(ROOT, "launch", "sweep"), "--no-build", os.path.join(ROOT, "scenes", "footing_small.toml"),
                        "--vary", "stage.penetrate.depth_ratio=0.02,0.03", "--into", into],
                       capture_output=True, text=True, timeout=170)
    check(r.returncode == 0, "sweep: exit %d:\n%s" % (r.returncode, r.stderr[-3000:]))
    rows = list(csv.DictReader(open(os.path.join(into, "index.csv")))) if os.path.exists(
        os.path.join(into, "index.csv")) else []
    check(len(rows) == 2, "index.csv: %d rows" % len(rows))
    if len(rows) == 2:
        check(rows[0]["branched_from"] == "", "run 1 branched: %s" % rows[0]["branched_from"])
        check(rows[1]["branched_from"].startswith("1/checkpoints/gravity-") and rows[1]["branched_from"].endswith("-end"),
              "run 2 did not start from run 1's gravity-end state: %r" % rows[1]["branched_from"])
        for row in rows:
            check(row["status"] == "finished" and row["target_reached"] == "true", "run %s: %s" % (row["run"], row))
            for k in ("peak_N", "k_e_N_m", "final_N"):
                try:
                    ok = float(row[k]) > 0
                except ValueError:
                    ok = False
                check(ok, "run %s: %s = %r" % (row["run"], k, row[k]))
        summary = open(os.path.join(into, "2", "summary.txt")).read()
        check("branched from" in summary, "run 2's summary does not say it branched")
        check(not os.path.exists(os.path.join(into, "2", "history_4_gravity.csv")) and
              os.path.exists(os.path.join(into, "2", "history_5_penetrate.csv")), "run 2 ran the stages before penetrate")
        js = json.load(open(os.path.join(into, "index.json")))
        check(js["runs"][1]["branched_from"] == rows[1]["branched_from"] and js["runs"][1]["target_reached"] is True and
              js["runs"][1]["keys"] == {"stage.penetrate.depth_ratio": "0.03"}, "index.json: %s" % js["runs"][1])
        check(float(rows[1]["final_N"]) != float(rows[0]["final_N"]), "both runs give the same final load")
finally:
    if fails:
        print("FAIL (kept %s):\n  %s" % (tmp, "\n  ".join(fails)))
    else:
        shutil.rmtree(tmp, ignore_errors=True)
if fails:
    sys.exit(1)
print("sweep_branch: all checks passed")

#!/usr/bin/python3
"""ctest sweep_e2e: launch/sweep end to end on the chain scene (scenes/chain_serial.toml, about
1.5 s a run) with the executables of DEMFDM_BUILD.
- A 2 x 2 sweep (chain.stiffness, stage.wave.steps) with 2 seeds, 2 runs at once: exit 0, 8 run
  folders, index.csv and index.json with 8 rows (keys, seed, run folder, status finished, exit
  code 0, wall time), each run's scene.toml has its values and seed and its history its steps;
  the stiffness changes the motion.
- Rerun with --into (same arguments, and --into alone): nothing runs (no run folder changes).
- A run whose folder is unfinished (summary.json removed) is rerun, the old folder kept.
- A bad combination (chain.split=30 with 20 masses) stops the sweep before any run: exit 2, one
  line naming the run and the override, no sweep folder.
- --check validates list values split on the commas at bracket depth 0 (footing scene).
Usage: check_sweep_e2e.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = sys.argv[1]
SWEEP = os.path.join(ROOT, "launch", "sweep")
CHAIN = os.path.join(ROOT, "scenes", "chain_serial.toml")
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


def sweep(args, timeout=150):
    return subprocess.run([SWEEP, "--no-build"] + args, capture_output=True, text=True, timeout=timeout)


def snapshot(folder):
    """{path: mtime} of every file in the sweep's run folders."""
    out = {}
    for d, _, files in os.walk(folder):
        if os.path.relpath(d, folder).split(os.sep)[0].isdigit():
            for f in files:
                out[os.path.join(d, f)] = os.stat(os.path.join(d, f)).st_mtime_ns
    return out


tmp = tempfile.mkdtemp(prefix="demfdm-sweep-e2e-")
try:
    into = os.path.join(tmp, "sw")
    args = [CHAIN, "--vary", "chain.stiffness=100,200", "--vary", "stage.wave.steps=40,80", "--seeds", "2",
            "--jobs", "2", "--into", into]
    r = sweep(args)
    check(r.returncode == 0, "sweep: exit %d:\n%s" % (r.returncode, r.stderr[-3000:]))
    rows = list(csv.DictReader(open(os.path.join(into, "index.csv")))) if os.path.exists(
        os.path.join(into, "index.csv")) else []
    js = json.load(open(os.path.join(into, "index.json"))) if os.path.exists(os.path.join(into, "index.json")) else {}
    check(len(rows) == 8, "index.csv: %d rows, expected 8" % len(rows))
    check(len(js.get("runs", [])) == 8, "index.json: %d runs, expected 8" % len(js.get("runs", [])))
    expect = [(s, n, k) for s in ("100", "200") for n in ("40", "80") for k in ("1", "2")]
    finals = {}
    for row, (stiff, steps, seed) in zip(rows, expect):
        tag = "run %s" % row["run"]
        check((row["chain.stiffness"], row["stage.wave.steps"], row["seed"]) == (stiff, steps, seed),
              "%s: keys %s" % (tag, row))
        check(row["status"] == "finished" and row["exit_code"] == "0" and float(row["wall_s"]) > 0,
              "%s: status %s exit %s wall %s" % (tag, row["status"], row["exit_code"], row["wall_s"]))
        d = os.path.join(into, row["run_dir"])
        check(os.path.isfile(os.path.join(d, "summary.json")), "%s: no finished run in %s" % (tag, d))
        sc = open(os.path.join(d, "scene.toml")).read() if os.path.exists(os.path.join(d, "scene.toml")) else ""
        check("\nstiffness = %s\n" % stiff in sc and "\nsteps = %s\n" % steps in sc and "\nseed = %s\n" % seed in sc,
              "%s: scene.toml without stiffness %s, steps %s, seed %s" % (tag, stiff, steps, seed))
        hist = os.path.join(d, "history_0_wave.csv")
        lines = open(hist).read().strip().split("\n") if os.path.exists(hist) else []
        check(len(lines) == int(steps) + 1, "%s: %d history rows, expected %s" % (tag, len(lines) - 1, steps))
        if lines:
            finals[(stiff, steps, seed)] = lines[-1].split(",", 1)[1]
    if len(finals) == 8:
        check(finals[("100", "80", "1")] != finals[("200", "80", "1")], "the stiffness does not change the motion")
        check(finals[("100", "80", "1")] == finals[("100", "80", "2")], "the chain does not depend on the seed")
    check(not os.path.exists(os.path.join(into, "1", "traffic.lcmlog")), "a sweep run recorded traffic")

    # Rerun: nothing new.
    before = snapshot(into)
    for again in (args, ["--into", into]):
        r = sweep(again)
        check(r.returncode == 0 and "8 finished before, 0 to run" in r.stderr,
              "rerun %s: exit %d: %s" % (again[-2:], r.returncode, r.stderr[-1500:]))
    check(snapshot(into) == before, "a rerun changed run folders")
    rows2 = list(csv.DictReader(open(os.path.join(into, "index.csv"))))
    check(rows2 == rows, "the rerun changed the index")

    # An unfinished run is rerun, its folder kept aside.
    os.remove(os.path.join(into, "3", "summary.json"))
    r = sweep(["--into", into])
    check(r.returncode == 0 and "7 finished before, 1 to run" in r.stderr, "resume: exit %d: %s" %
          (r.returncode, r.stderr[-1500:]))
    check(os.path.isdir(os.path.join(into, "3.incomplete-1")) and
          os.path.isfile(os.path.join(into, "3", "summary.json")), "run 3 not rerun, or its old folder not kept")
    rows3 = list(csv.DictReader(open(os.path.join(into, "index.csv"))))
    check(len(rows3) == 8 and all(x["status"] == "finished" for x in rows3), "index after the resume: %s" % rows3)

    # A bad combination: nothing starts.
    root = os.path.join(tmp, "runs")
    os.makedirs(root)
    r = sweep([CHAIN, "--vary", "chain.split=5,30", "--runs-root", root])
    lines = r.stderr.strip().split("\n")
    check(r.returncode == 2 and len(lines) == 1 and lines[0].startswith(
        "sweep: run 2 (chain.split=30): --set chain.split=30: expected an integer in [1, n_masses-1]"),
        "bad combination: exit %d: %r" % (r.returncode, r.stderr))
    check(os.listdir(root) == [], "a sweep folder was created for a bad sweep: %s" % os.listdir(root))

    # List values keep their commas (validated only).
    r = sweep([os.path.join(ROOT, "scenes", "footing_small.toml"), "--vary",
               "continuum.mesh.size=[4e-3,4e-3,4e-3],[5e-3, 5e-3, 5e-3]", "--vary", "stage.penetrate.inertial_number=1e-3,2e-3", "--check"])
    check(r.returncode == 0 and "4 combination(s) valid" in r.stderr, "--check with list values: exit %d: %s" %
          (r.returncode, r.stderr))
finally:
    if fails:
        print("FAIL (kept %s):\n  %s" % (tmp, "\n  ".join(fails)))
    else:
        shutil.rmtree(tmp, ignore_errors=True)
if fails:
    sys.exit(1)
print("sweep_e2e: all checks passed")

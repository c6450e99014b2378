#!/usr/bin/python3
"""ctest hertz_runs: two whole runs with the Hertz-Mindlin law (docs/theory.md 1.9).

1. scenes/hertz_rev.toml: Hertz-Mindlin ball-ball contacts, an unbonded REV generated, servoed
isotropically to 12.5 kPa and cycled. Checks: exit 0; the servo stage's Love-Weber stress is
12.5 kPa within 0.5 % on every axis (the servo's criterion) at a porosity below the loose
generation's 0.52 and a coordination above 4 (a jammed, load-carrying packing); the cycle stage
ends with an unbalanced ratio below 1e-5.

2. scenes/footing_small.toml with Hertz-Mindlin ball-footing contacts
(`launch/run SCENE --set dem.ball_footing.model=hertz --set stage.penetrate.depth_ratio=0.05
--no-build --run-dir DIR`), with the executables of DEMFDM_BUILD. Checks: exit 0; the effective
scene records the law; the footing, whose reaction comes only from its Hertz contacts, carried a
load and reached its target settlement. The same run with `--set dem.ball_footing.model=hertzz` is refused at --check with exit 2
naming the key. The temp folder is removed when the test passes, kept otherwise.
Usage: check_hertz_footing.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile

sys.dont_write_bytecode = True
ROOT = sys.argv[1]
DEPTH_RATIO = 0.05
D_F = 0.4e-3  # scenes/footing_small.toml [dem.footing] diameter


def main():
    failures = []
    tmp = tempfile.mkdtemp(prefix="demfdm-hertz-")
    scene = os.path.join(ROOT, "scenes", "footing_small.toml")
    run_dir = os.path.join(tmp, "run")
    launch = os.path.join(ROOT, "launch", "run")
    try:
        r = subprocess.run([launch, scene, "--set", "dem.ball_footing.model=hertz", "--set",
                            "stage.penetrate.depth_ratio=%g" % DEPTH_RATIO, "--no-build", "--run-dir", run_dir],
                           capture_output=True, text=True, timeout=140)
    except subprocess.TimeoutExpired:
        print("FAIL: the Hertz footing run did not finish in 140 s; kept %s" % tmp)
        return 1
    print(r.stdout[-1500:])
    if r.returncode != 0:
        failures.append("launch/run exited %d:\n%s" % (r.returncode, r.stderr[-3000:]))
    else:
        text = open(os.path.join(run_dir, "scene.toml")).read()
        sec = text[text.find("[dem.ball_footing]"):]
        sec = sec[:sec.find("\n[", 1)] if "\n[" in sec[1:] else sec
        if 'model = "hertz"' not in sec:
            failures.append("the effective scene's [dem.ball_footing] does not set model = \"hertz\":\n" + sec)
        res = json.load(open(os.path.join(run_dir, "summary.json")))["result"]
        print("result: %s" % res)
        if not (res["peak_N"] > 0.0 and res["k_e_N_m"] > 0.0):
            failures.append("the footing carried no load: %s" % res)
        if not res["target_reached"] or abs(res["final_settlement_m"] - DEPTH_RATIO * D_F) > 0.05 * DEPTH_RATIO * D_F:
            failures.append("the footing did not reach %g D_f: %s" % (DEPTH_RATIO, res))
    bad = subprocess.run([launch, scene, "--set", "dem.ball_footing.model=hertzz", "--check", "--no-build"],
                         capture_output=True, text=True, timeout=60)
    msg = bad.stdout + bad.stderr
    if bad.returncode != 2 or "dem.ball_footing.model" not in msg or "hertz" not in msg:
        failures.append("an unknown law was not refused at --check with exit 2 naming the key (exit %d):\n%s" %
                        (bad.returncode, msg[-1500:]))
    rev_dir = os.path.join(tmp, "rev")
    r = subprocess.run([launch, os.path.join(ROOT, "scenes", "hertz_rev.toml"), "--no-build", "--run-dir", rev_dir],
                       capture_output=True, text=True, timeout=140)
    print(r.stdout[-800:])
    if r.returncode != 0:
        failures.append("hertz_rev exited %d:\n%s" % (r.returncode, r.stderr[-3000:]))
    else:
        with open(os.path.join(rev_dir, "specimen_stages.csv")) as f:
            rows = list(csv.DictReader(f))
        servo = rows[-1]
        print("servo stage: %s" % servo)
        for k in ("sxx_Pa", "syy_Pa", "szz_Pa"):
            if abs(-float(servo[k]) - 12.5e3) > 0.005 * 12.5e3:
                failures.append("hertz_rev: %s = %s Pa, expected -12500 within 0.5 %%" % (k, servo[k]))
        if not (float(servo["porosity_unit"]) < 0.52 and float(servo["coordination_unit"]) > 4.0):
            failures.append("hertz_rev: not a jammed packing after the servo: %s" % servo)
        with open(os.path.join(rev_dir, "history_2_cycle.csv")) as f:
            last = list(csv.DictReader(f))[-1]
        if not float(last["dem.ratio"]) < 1e-5:
            failures.append("hertz_rev: the cycle ends at ratio %s" % last["dem.ratio"])
    if failures:
        print("FAIL:\n" + "\n".join(failures) + "\nkept %s" % tmp)
        return 1
    shutil.rmtree(tmp, ignore_errors=True)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())

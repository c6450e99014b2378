#!/usr/bin/python3
"""ctest ensemble_e2e: `launch/run SCENE --seeds 2 --set stage.penetrate.depth_ratio=0.05 --no-build
--run-dir DIR` end to end on a tiny footing (scenes/footing_small.toml penetrated to 0.05 D_f
instead of 0.2, as an override), with the executables of DEMFDM_BUILD. Checks: exit 0; both seed
runs finished with their own seed and the override in the scene they record; ensemble.csv, ensemble_stats.csv, ensemble.md and
ensemble.png exist (the PNG with its signature); n = 2 on every row of ensemble.csv and for the
peak; the band contains the mean everywhere and is not empty (two seeds give two curves); the
curves end near 0.05 D_f. The temp folder is removed when the test passes, kept otherwise.
Usage: check_ensemble_e2e.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
ROOT = sys.argv[1]

DEPTH_RATIO = 0.05
D_F = 0.4e-3  # scenes/footing_small.toml [dem.footing] diameter


def main():
    failures = []
    tmp = tempfile.mkdtemp(prefix="demfdm-ensemble-e2e-")
    scene = os.path.join(ROOT, "scenes", "footing_small.toml")
    ens = os.path.join(tmp, "ens")
    t0 = time.time()
    try:
        r = subprocess.run([os.path.join(ROOT, "launch", "run"), scene, "--seeds", "2", "--set",
                            "stage.penetrate.depth_ratio=%g" % DEPTH_RATIO, "--no-build", "--run-dir", ens],
                           capture_output=True, text=True, timeout=110)
    except subprocess.TimeoutExpired:
        print("FAIL: launch/run --seeds 2 did not finish in 110 s; kept %s" % tmp)
        return 1
    wall = time.time() - t0
    print("launch/run --seeds 2: exit %d in %.1f s" % (r.returncode, wall))
    if r.returncode != 0:
        failures.append("launch/run --seeds 2 exited %d:\n%s\n%s" % (r.returncode, r.stdout[-2000:], r.stderr[-3000:]))
    for k in (1, 2):
        d = os.path.join(ens, "seed-%d" % k)
        if not os.path.exists(os.path.join(d, "summary.json")):
            failures.append("seed %d: no finished run in %s" % (k, d))
        else:
            text = open(os.path.join(d, "scene.toml")).read()
            if "\nseed = %d\n" % k not in text:
                failures.append("seed %d: the run's scene does not set seed = %d" % (k, k))
            if "\ndepth_ratio = %g\n" % DEPTH_RATIO not in text or "--set run.seed=%d" % k not in text:
                failures.append("seed %d: the run's scene.toml is not the effective scene with the overrides" % k)
    for f in ("ensemble.csv", "ensemble_stats.csv", "ensemble.md", "ensemble.png"):
        if not os.path.isfile(os.path.join(ens, f)) or os.path.getsize(os.path.join(ens, f)) == 0:
            failures.append("no %s" % f)
    if not failures:
        if open(os.path.join(ens, "ensemble.png"), "rb").read(8) != b"\x89PNG\r\n\x1a\n":
            failures.append("ensemble.png is not a PNG")
        with open(os.path.join(ens, "ensemble.csv")) as f:
            rows = list(csv.DictReader(f))
        if len(rows) < 10:
            failures.append("ensemble.csv: %d rows" % len(rows))
        if any(int(r["n"]) != 2 for r in rows):
            failures.append("ensemble.csv: n is not 2 on every row")
        lo = [float(r["band_low_N"]) for r in rows]
        mean = [float(r["mean_load_N"]) for r in rows]
        hi = [float(r["band_high_N"]) for r in rows]
        if not all(a <= m <= b for a, m, b in zip(lo, mean, hi)):
            failures.append("the band does not contain the mean everywhere")
        if not any(b - a > 1e-6 * max(abs(x) for x in mean) for a, b in zip(lo, hi)):
            failures.append("the band is empty: the two seeds gave the same curve?")
        end = float(rows[-1]["disp_m"])
        if not 0.8 * DEPTH_RATIO * D_F < end < 1.2 * DEPTH_RATIO * D_F:
            failures.append("the common stroke ends at %.4g m, expected about %.4g m" % (end, DEPTH_RATIO * D_F))
        with open(os.path.join(ens, "ensemble_stats.csv")) as f:
            stats = {r["measure"]: r for r in csv.DictReader(f)}
        pk = stats.get("peak_N")
        if pk is None or int(pk["n"]) != 2:
            failures.append("ensemble_stats.csv: peak_N n is not 2: %s" % pk)
        else:
            print("peak %.4g +- %.2g N (95 %% CI, n = 2); seeds %s, %s N; mean load over the stroke %.4g N" % (
                float(pk["mean"]), float(pk["ci95_half"]), pk["seed_1"], pk["seed_2"],
                float(stats["mean_load_all_N"]["mean"])))
        md = open(os.path.join(ens, "ensemble.md")).read()
        if "n = 2" not in md:
            failures.append("ensemble.md does not give n = 2")
        if "ensemble.md" not in r.stderr or "ensemble.png" not in r.stderr:
            failures.append("launch/run does not say where the table and figure are:\n%s" % r.stderr[-1000:])
    for f in failures:
        print("FAIL:", f)
    if failures:
        print("kept %s" % tmp)
        return 1
    shutil.rmtree(tmp)
    print("check_ensemble_e2e.py: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

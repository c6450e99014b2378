#!/usr/bin/python3
"""ctest ensemble_unit: the statistics of launch/py/ensemble.py against hand numbers and closed
forms, and its run/table commands on stand-ins (no simulator):
  * t975: the table against printed values (3 decimals), every table entry against an
    independent numerical integration of the Student-t density (CDF = 0.975 to 1e-6), and the
    large-dof expansion against printed values at 40, 60, 120 dof and the normal limit;
  * scalar_stats on hand-computed samples (NaNs left out, n = 1 and n = 0);
  * interval_means on a linear load (each interval's mean is the load at its midpoint, also with
    interval edges between samples and uneven sampling) and on a quadratic (exact integral);
  * curve_stats / common_grid on synthetic curves y = a_i d with different strokes and samplings
    (mean, se, band, n, the common range);
  * parse_seeds and seed_sets (the overrides of a seed's run: --set, --stage-set as stage.STAGE.key,
    run.seed, no traffic log unless the scene or an override says traffic_log; malformed ones fail);
  * `table` on fake run folders (history CSV, summary.json, scene.toml): the files, n, the
    measures per seed, an unfinished seed left out and named;
  * `run` with a stand-in launcher (--launcher) on scenes/chain_serial.toml and the build's
    coordinator (it checks the overrides and writes the effective scene a run records): every seed
    runs the scene file with --set overrides (no scene text is written), J = 2 runs at once, a
    failing seed named with its exit code and last output lines and exit 3 after the others
    finish, resume (finished seeds not rerun, the unfinished folder kept as
    seed-<k>.incomplete-1), a seed folder written before ensembles used overrides (an edited copy
    of the scene as its scene.toml) counts as finished, other values refused, --check runs
    nothing, a bad --set fails with exit 2 before anything runs.
Usage: check_ensemble.py LAUNCH_PY_FOLDER   (environment: DEMFDM_BUILD, default the source's build/)
"""
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
TOOLS = sys.argv[1]
sys.path.insert(0, TOOLS)
import numpy as np  # noqa: E402
import ensemble  # noqa: E402
import branching  # noqa: E402

failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)


def close(a, b, tol, what):
    ok = (math.isnan(a) and math.isnan(b)) or abs(a - b) <= tol * max(1.0, abs(b))
    check(ok, "%s: got %r, expected %r (tol %g)" % (what, a, b, tol))


def t_cdf(x, v):
    """Student-t CDF by Simpson integration of the density from 0 to x (independent of the table)."""
    c = math.exp(math.lgamma((v + 1) / 2) - math.lgamma(v / 2)) / math.sqrt(v * math.pi)
    n = 200000
    s = np.linspace(0.0, x, n + 1)
    f = c * (1 + s * s / v) ** (-(v + 1) / 2)
    h = x / n
    return 0.5 + h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())


def test_t():
    printed = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 10: 2.228, 15: 2.131, 20: 2.086, 25: 2.060,
               30: 2.042, 40: 2.021, 60: 2.000, 120: 1.980, 10 ** 7: 1.960}
    for v, t in printed.items():
        close(ensemble.t975(v), t, 6e-4 / t, "t975(%d) against the printed table" % v)
    for v in range(1, 31):
        close(t_cdf(ensemble.t975(v), v), 0.975, 1e-6, "Student-t CDF at t975(%d)" % v)
    for v in (31, 35, 50):  # the expansion beyond the table, against the same integration
        close(t_cdf(ensemble.t975(v), v), 0.975, 1e-6, "Student-t CDF at t975(%d) (expansion)" % v)
    check(ensemble.t975(31) < ensemble.t975(30), "t975 must decrease from 30 to 31 dof")
    check(math.isnan(ensemble.t975(0)), "t975(0) must be NaN")


def test_scalar_stats():
    m, se, h, n = ensemble.scalar_stats([1, 2, 3, 4, 5])
    # sd = sqrt(10/4) = 1.58114, se = sd/sqrt(5) = 0.707107, half = 2.776445 * se = 1.963243
    close(m, 3.0, 1e-12, "mean of 1..5")
    close(se, math.sqrt(0.5), 1e-12, "se of 1..5")
    close(h, 2.776445105 * math.sqrt(0.5), 1e-9, "95 % half-width of 1..5")
    check(n == 5, "n of 1..5: %d" % n)
    m, se, h, n = ensemble.scalar_stats([1.0, float("nan"), 3.0])
    # two values: sd = sqrt(2), se = 1, half = 12.706205
    close(m, 2.0, 1e-12, "mean with a NaN left out")
    close(se, 1.0, 1e-12, "se with a NaN left out")
    close(h, 12.706204736, 1e-9, "half-width, 1 dof")
    check(n == 2, "n with a NaN left out: %d" % n)
    m, se, h, n = ensemble.scalar_stats([0.7])
    check(m == 0.7 and math.isnan(se) and math.isnan(h) and n == 1, "one value: %r" % ((m, se, h, n),))
    m, se, h, n = ensemble.scalar_stats([])
    check(math.isnan(m) and n == 0, "no value: %r" % ((m, se, h, n),))
    m, se, h, n = ensemble.scalar_stats([10.0, 12.0, 14.0, 16.0])
    # mean 13, sd = sqrt(20/3) = 2.5819889, se = sd / 2 = 1.2909944, half = 3.1824463 * se = 4.1085205
    close(h, 4.1085205, 1e-7, "half-width of 10, 12, 14, 16")


def test_interval_means():
    rng = np.random.default_rng(7)
    d = np.sort(np.concatenate(([0.0, 1.0], rng.uniform(0, 1, 300))))  # uneven sampling
    f = 3.0 + 2.0 * d
    edges = [0.0, 0.13, 0.5, 0.77, 1.0]  # edges between samples
    got = ensemble.interval_means(d, f, edges)
    for a, b, g in zip(edges[:-1], edges[1:], got):
        close(g, 3.0 + 2.0 * 0.5 * (a + b), 1e-12, "linear load, interval mean over [%g, %g] = midpoint value" % (a, b))
    # A linear load sampled very unevenly: a sample mean would be biased, the stroke mean is not.
    d2 = np.concatenate((np.linspace(0, 0.1, 1000), np.linspace(0.1, 1.0, 10)[1:]))
    g = ensemble.interval_means(d2, 5.0 * d2, [0.0, 1.0])[0]
    close(g, 2.5, 1e-12, "linear load, dense samples at the start: stroke-weighted mean")
    dq = np.linspace(0, 2, 20001)
    for a, b, g in zip([0, 0.5, 1.5], [0.5, 1.5, 2.0], ensemble.interval_means(dq, dq ** 2, [0, 0.5, 1.5, 2.0])):
        close(g, (b ** 3 - a ** 3) / (3 * (b - a)), 1e-7, "quadratic load, mean over [%g, %g]" % (a, b))
    check(math.isnan(ensemble.interval_means(d, f, [0.5, 1.5])[0]), "an interval beyond the curve must give NaN")


def test_curve_stats():
    a = np.array([1.0, 2.0, 4.0])  # slopes
    curves = [(np.linspace(0, 1.0, 50), None), (np.linspace(0, 0.8, 333), None), (np.linspace(0.1, 1.2, 71), None)]
    curves = [(x, ai * x) for (x, _), ai in zip(curves, a)]
    grid = ensemble.common_grid(curves)
    close(grid[0], 0.1, 1e-12, "common range start")
    close(grid[-1], 0.8, 1e-12, "common range end")
    # Samples in [0.1, 0.8]: curve 1 (step 1/49) 35, curve 2 (step 0.8/332) 291, curve 3 (step 1.1/70) 45.
    check(len(grid) == 35, "default grid points: the sparsest curve's samples in the range (%d, expected 35)" % len(grid))
    cs = ensemble.curve_stats(curves, grid)
    sd = np.std(a, ddof=1)
    check(cs["n"] == 3, "n = %d" % cs["n"])
    check(np.allclose(cs["mean"], a.mean() * grid, rtol=1e-12, atol=1e-14), "mean curve = mean slope x d")
    check(np.allclose(cs["se"], sd / math.sqrt(3) * grid, rtol=1e-12, atol=1e-14), "se = sd(slopes)/sqrt(3) x d")
    check(np.allclose(cs["high"] - cs["mean"], 4.302652730 * sd / math.sqrt(3) * grid, rtol=1e-9, atol=1e-14),
          "band half-width = t975(2) se")
    check(np.all(cs["low"] <= cs["mean"]) and np.all(cs["mean"] <= cs["high"]), "the band contains the mean")
    one = ensemble.curve_stats(curves[:1], grid)
    check(one["n"] == 1 and np.allclose(one["low"], one["mean"]) and np.all(np.isnan(one["se"])),
          "one curve: no band")
    try:
        ensemble.common_grid([(np.array([0.0, 1.0]), np.zeros(2)), (np.array([2.0, 3.0]), np.zeros(2))])
        failures.append("disjoint curves must raise")
    except ValueError:
        pass


SCENE = """[run]
name = "fake"
seed = 3
threads = 1

[dem.footing]
diameter = 0.4e-3

[[stage]]
name = "gravity"
action = "couple"
steps = 10

[[stage]]
name = "penetrate"
action = "penetrate"
steps = 100
"""


def test_scene_edits(tmp):
    check(ensemble.parse_seeds("3") == [1, 2, 3], "seeds 3")
    check(ensemble.parse_seeds("4-6") == [4, 5, 6], "seeds 4-6")
    check(ensemble.parse_seeds("1,4,7-9") == [1, 4, 7, 8, 9], "seeds 1,4,7-9")
    for bad in ("0", "x", "5-2", "1,,2", ""):
        try:
            ensemble.parse_seeds(bad)
            failures.append("seeds %r must be refused" % bad)
        except ValueError:
            pass
    scene = os.path.join(tmp, "edits.toml")
    open(scene, "w").write(SCENE)
    before = open(scene).read()
    s = ensemble.seed_sets(scene, 7, ["dem.footing.diameter=0.5e-3"], ["penetrate.depth_ratio=0.05"])
    check(s == ["dem.footing.diameter=0.5e-3", "stage.penetrate.depth_ratio=0.05", "run.seed=7",
                "output.traffic_log=false"], "seed_sets: --set, --stage-set, seed, no traffic log: %s" % s)
    check(open(scene).read() == before, "the scene file must not change")
    s = ensemble.seed_sets(scene, 2, ["output.traffic_log=true"])
    check(s == ["output.traffic_log=true", "run.seed=2"], "an override that says traffic_log keeps it: %s" % s)
    open(scene, "w").write(SCENE + "\n[output]\ntraffic_log = true\n")
    check(ensemble.seed_sets(scene, 5) == ["run.seed=5"], "a scene that says traffic_log keeps it")
    open(scene, "w").write(SCENE + "\n[output]\nx = 1\n")
    check(ensemble.seed_sets(scene, 5) == ["run.seed=5", "output.traffic_log=false"],
          "an [output] table without traffic_log gets traffic_log=false")
    for sets, stages in ((["nodot=1"], []), (["dem.x"], []), ([], ["nostage=1"]), ([], [".steps=1"])):
        try:
            ensemble.seed_sets(scene, 1, sets, stages)
            failures.append("override %s %s must fail" % (sets, stages))
        except KeyError:
            pass


def fake_run(d, seed, slope, wall, stroke=1e-4, failed=False):
    """A run folder as launch/run leaves it: scene.toml, history_4_penetrate.csv, summary.json/txt."""
    os.makedirs(d)
    open(os.path.join(d, "scene.toml"), "w").write(SCENE.replace("seed = 3", "seed = %d" % seed))
    if failed:
        open(os.path.join(d, "summary.txt"), "w").write("FAILED: a node died\n")
        return
    n = 400
    disp = np.linspace(1e-9, stroke, n)
    load = slope * disp
    load[n // 2] += 5.0  # one spike: the raw peak; barely moves the interval means
    fail = (disp > 0.3 * stroke).astype(int) * 3
    with open(os.path.join(d, "history_4_penetrate.csv"), "w") as f:
        f.write("step,dem.bond_failures,dem.footing_disp_m,dem.footing_fz_N\n")
        for i in range(n):
            f.write("%d,%d,%.12g,%.12g\n" % (i, fail[i], disp[i], load[i]))
    json.dump({"totals": {"steps": n, "wall_s": wall, "nodes": {}}}, open(os.path.join(d, "summary.json"), "w"))
    open(os.path.join(d, "summary.txt"), "w").write("total: %d coupling steps in %g s\n" % (n, wall))


def test_table(tmp):
    before = len(failures)
    ens = os.path.join(tmp, "table")
    os.makedirs(ens)
    slopes = {1: 1e4, 2: 2e4, 3: 3e4}
    for k, s in slopes.items():
        fake_run(os.path.join(ens, "seed-%d" % k), k, s, wall=10.0 * k, stroke=1e-4 if k != 3 else 1.2e-4)
    fake_run(os.path.join(ens, "seed-4"), 4, 0, 0, failed=True)
    os.makedirs(os.path.join(ens, "seed-5.incomplete-1"))  # not a seed folder
    r = subprocess.run([sys.executable, os.path.join(TOOLS, "ensemble.py"), "table", ens, "--intervals", "4"],
                       capture_output=True, text=True)
    check(r.returncode == 0, "table failed: %s %s" % (r.stdout, r.stderr))
    check("seed 4 not included" in r.stderr and "FAILED" in r.stderr, "the failed seed must be named: %s" % r.stderr)
    for f in ("ensemble.csv", "ensemble_stats.csv", "ensemble.md", "ensemble.png"):
        check(os.path.isfile(os.path.join(ens, f)) and os.path.getsize(os.path.join(ens, f)) > 0, "no %s" % f)
    if len(failures) > before:
        return
    c = ensemble.paper_figures.read_csv(os.path.join(ens, "ensemble.csv"))
    check(np.all(c["n"] == 3), "ensemble.csv n must be 3")
    close(c["disp_m"][-1], 1e-4, 1e-9, "mean curve ends where the shortest stroke ends")
    rows = {}
    import csv
    with open(os.path.join(ens, "ensemble_stats.csv")) as f:
        for row in csv.DictReader(f):
            rows[row["measure"]] = row
    pk = rows["peak_N"]
    check(int(pk["n"]) == 3, "peak n")
    # Seeds 1, 2: peak = spike + slope x d at row 200 (d = 1e-9 + 200 (1e-4 - 1e-9)/399); seed 3 its own stroke.
    d1 = 1e-9 + 200 * (1e-4 - 1e-9) / 399
    d3 = 1e-9 + 200 * (1.2e-4 - 1e-9) / 399
    peaks = [5 + 1e4 * d1, 5 + 2e4 * d1, 5 + 3e4 * d3]
    close(float(pk["mean"]), np.mean(peaks), 1e-6, "peak mean")
    close(float(pk["ci95_half"]), 4.302652730 * np.std(peaks, ddof=1) / math.sqrt(3), 1e-6, "peak CI")
    close(float(rows["wall_s"]["mean"]), 20.0, 1e-9, "wall mean")
    close(float(rows["wall_s"]["ci95_half"]), 4.302652730 * 10 / math.sqrt(3), 1e-6, "wall CI")
    # k_e: the fit before the first bond failure of a straight line = its slope.
    close(float(rows["k_e_N_m"]["seed_2"]), 2e4, 1e-6, "k_e of seed 2")
    # Interval 4 of the common range [1e-9, 1e-4] holds no spike for seeds 1, 2 (the spike of seed 3 is at
    # 0.6e-4, in interval 3): mean = slope x midpoint.
    lo, hi = 1e-9, 1e-4
    a, b = lo + 0.75 * (hi - lo), hi
    close(float(rows["mean_load_4_N"]["seed_1"]), 1e4 * 0.5 * (a + b), 1e-6, "interval 4 mean of seed 1")
    md = open(os.path.join(ens, "ensemble.md")).read()
    check("n = 3" in md and "common grid" in md and "seed 4" in md, "ensemble.md: n, grid note, left-out seed")


LAUNCHER = r"""#!/usr/bin/python3
# Stand-in for launch/run: "SCENE --check --no-build --set=K=V ..." (the coordinator checks) or
# "SCENE --no-build --set=K=V ... --run-dir DIR" (the run folder gets the effective scene, as
# launch/run writes it, and a fake history whose load grows with the seed).
import json, os, subprocess, sys, time
a = sys.argv[1:]
scene = a[0]
sets = [x for x in a if x.startswith("--set=")]
seed = int([x for x in sets if x.startswith("--set=run.seed=")][-1].split("=")[-1])
coord = os.environ["FAKE_COORD"]
open(os.environ["FAKE_LOG"], "a").write("%s %d %.3f\n" % ("check" if "--check" in a else "run", seed, time.time()))
if "--check" in a:
    sys.exit(subprocess.call([coord, scene, "--check"] + sets))
d = a[a.index("--run-dir") + 1]
os.makedirs(d)
eff = subprocess.run([coord, scene, "--print-effective"] + sets, capture_output=True, text=True, check=True).stdout
open(os.path.join(d, "scene.toml"), "w").write(eff)
time.sleep(0.6)
open(os.environ["FAKE_LOG"], "a").write("done %d %.3f\n" % (seed, time.time()))
if seed == int(os.environ.get("FAKE_FAIL", "0")):
    print("node dem: blow-up at step 12")
    print("launch/run: finished with code 3; run folder " + d)
    sys.exit(3)
with open(os.path.join(d, "history_1_penetrate.csv"), "w") as f:
    f.write("step,dem.footing_disp_m,dem.footing_fz_N\n")
    for i in range(50):
        f.write("%d,%g,%g\n" % (i, i * 1e-6, seed * i * 1e-2))
json.dump({"totals": {"steps": 50, "wall_s": 0.6, "nodes": {}}}, open(os.path.join(d, "summary.json"), "w"))
open(os.path.join(d, "summary.txt"), "w").write("total: 50 coupling steps in 0.6 s\n")
"""


def calls(log, kind):
    return [line.split() for line in open(log) if line.startswith(kind + " ")] if os.path.exists(log) else []


def test_run(tmp):
    coord = branching.coordinator_command()[0]
    if not os.access(coord, os.X_OK):
        failures.append("no coordinator at %s (set DEMFDM_BUILD)" % coord)
        return
    launcher = os.path.join(tmp, "fake_run")
    open(launcher, "w").write(LAUNCHER)
    os.chmod(launcher, 0o755)
    chain = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(TOOLS))), "scenes", "chain_serial.toml")
    scene = os.path.join(tmp, "chain.toml")
    shutil.copy(chain, scene)
    text = open(scene).read()
    ens = os.path.join(tmp, "runs")
    log = os.path.join(tmp, "calls")
    env = dict(os.environ, FAKE_LOG=log, FAKE_FAIL="2", FAKE_COORD=coord)

    def ens_run(*extra, env=env):
        return subprocess.run([sys.executable, os.path.join(TOOLS, "ensemble.py"), "run", ens, "--scene", scene,
                               "--launcher", launcher] + list(extra), capture_output=True, text=True, env=env)

    r = ens_run("--seeds", "1-3", "--set", "dem.nope=1")
    check(r.returncode == 2 and "--set dem.nope=1" in r.stderr and "unknown key" in r.stderr,
          "a bad --set must fail with exit 2, naming it: %d %s" % (r.returncode, r.stderr))
    check(not calls(log, "run") and not os.path.exists(ens), "nothing may run after a bad --set")
    r = ens_run("--seeds", "1-3", "--check")
    check(r.returncode == 0 and "3 seed(s) checked" in r.stderr, "--check: %d %s" % (r.returncode, r.stderr))
    check(len(calls(log, "check")) >= 3 and not calls(log, "run") and not os.path.exists(ens),
          "--check must check every seed and run nothing")
    r = ens_run("--seeds", "3", "--jobs", "2")
    check(r.returncode == 3, "a failed seed must give exit 3 (got %d)" % r.returncode)
    check("seed 2 FAILED (exit code 3)" in r.stderr and "blow-up at step 12" in r.stderr,
          "the failed seed must be named with its exit code and last lines: %s" % r.stderr)
    check("FAILED seeds: seed-2 (exit code 3)" in r.stderr, "the final line must list the failed seeds: %s" % r.stderr)
    check(open(scene).read() == text and not [f for f in os.listdir(ens) if f.endswith(".toml")],
          "no scene text may be written: the scene file is run with overrides")
    for k in (1, 3):
        d = os.path.join(ens, "seed-%d" % k)
        check(os.path.exists(os.path.join(d, "summary.json")), "seed %d must finish" % k)
        eff = open(os.path.join(d, "scene.toml")).read()
        check("--set run.seed=%d" % k in eff and "\nseed = %d\n" % k in eff and "traffic_log = false" in eff,
              "seed-%d/scene.toml must be the effective scene with run.seed and no traffic log" % k)
    runs = [(int(s), float(t)) for _, s, t in calls(log, "run")]
    check(sorted(s for s, _ in runs) == [1, 2, 3], "runs: %s" % runs)
    ends = {int(s): float(t) for _, s, t in calls(log, "done")}
    first = sorted(runs, key=lambda x: x[1])[:2]
    check(len(runs) == 3 and len(first) == 2 and first[1][1] < ends.get(first[0][0], 0),
          "--jobs 2: the first two runs run at the same time: starts %s, ends %s" % (runs, ends))
    # Resume: seeds 1 and 3 are not rerun; the unfinished seed 2 is kept aside and runs again (now passing).
    if os.path.exists(log):
        os.remove(log)
    r = ens_run("--seeds", "3", env=dict(env, FAKE_FAIL="0"))
    check(r.returncode == 0, "resume must pass: %d %s" % (r.returncode, r.stderr))
    check([int(s) for _, s, _ in calls(log, "run")] == [2], "resume must run seed 2 only: %s" % calls(log, "run"))
    check(os.path.isdir(os.path.join(ens, "seed-2.incomplete-1")), "the failed folder must be kept")
    check("seeds 1,3 already finished" in r.stderr, "resume must say what it skips: %s" % r.stderr)
    # A seed folder of an ensemble written before ensembles used overrides: its scene.toml is an
    # edited copy of the scene (run.seed set, [output] traffic_log = false appended). It ran the
    # same values, so it counts as finished.
    old = os.path.join(ens, "seed-4")
    shutil.copytree(os.path.join(ens, "seed-1"), old)
    open(os.path.join(old, "scene.toml"), "w").write(
        text.replace('[run]\n', '[run]\nseed = 4\n', 1) + "\n[output]\ntraffic_log = false\n")
    if os.path.exists(log):
        os.remove(log)
    r = ens_run("--seeds", "4-4", env=dict(env, FAKE_FAIL="0"))
    check(r.returncode == 0 and not calls(log, "run") and "seeds 4 already finished" in r.stderr,
          "an old-style finished seed folder must be kept: %d %s" % (r.returncode, r.stderr))
    # A finished seed run with other values is refused.
    r = ens_run("--seeds", "1", "--set", "chain.stiffness=200")
    check(r.returncode == 2 and "different scene" in r.stderr, "changed values must be refused: %s" % r.stderr)
    r = subprocess.run([sys.executable, os.path.join(TOOLS, "ensemble.py"), "table", ens], capture_output=True, text=True)
    check(r.returncode == 0 and "n = 4" in r.stdout, "table after resume: %s %s" % (r.stdout[-300:], r.stderr))


def main():
    tmp = tempfile.mkdtemp(prefix="demfdm-ensemble-unit-")
    try:
        for t in (test_t, test_scalar_stats, test_interval_means, test_curve_stats):
            t()
        test_scene_edits(tmp)
        test_table(tmp)
        test_run(tmp)
    finally:
        if failures:
            print("kept %s" % tmp)
        else:
            shutil.rmtree(tmp)
    for f in failures:
        print("FAIL:", f)
    print("%s: %d failure(s)" % (os.path.basename(__file__), len(failures)))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""ctest run_set: launch/run --set with the executables of DEMFDM_BUILD.
- --check with a bad override (a bad value, an undeclared key, a stage that does not exist, a
  missing '='): exit 2 and one stderr line that names the override; with good ones: exit 0.
- A run with overrides (chain scene): its scene.toml is the effective scene, whose header names the
  scene and the overrides, with the overridden values, and the run used them (the history has the
  overridden number of steps); the same run without overrides but with the same values written in
  a scene file gives the same history bytes.
- --resume refuses --set.
- --seeds 2 with --set: both seed runs use the override and their own seed.
Usage: check_run_set.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = sys.argv[1]
RUN = os.path.join(ROOT, "launch", "run")
CHAIN = os.path.join(ROOT, "scenes", "chain_serial.toml")
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


def run(args, timeout=60):
    return subprocess.run([RUN] + args + ["--no-build"], capture_output=True, text=True, timeout=timeout)


tmp = tempfile.mkdtemp(prefix="demfdm-run-set-")
try:
    for bad, says in [
        (["--set", "chain.stiffness=abc"], "--set chain.stiffness=abc: expected a number > 0 N/m, found string 'abc'"),
        (["--set=chain.stifness=2"], "--set chain.stifness=2: unknown key 'chain.stifness'; did you mean 'chain.stiffness'?"),
        (["--set", "stage.unload.steps=3"], "--set stage.unload.steps=3: no [[stage]] named 'unload' (the scene's: wave)"),
        (["--set", "stage[1].steps=3"], "--set stage[1].steps=3: no element stage[1]: the scene has 1 [[stage]] table"),
        (["--set", "chain.stiffness"], "--set chain.stiffness: expected table.key=value"),
        (["--set", "chain.split=20"], "--set chain.split=20: expected an integer in [1, n_masses-1]"),
    ]:
        r = run([CHAIN, "--check"] + bad)
        lines = r.stderr.strip().split("\n")
        check(r.returncode == 2, "%s: exit %d, expected 2" % (bad, r.returncode))
        check(len(lines) == 1 and lines[0].startswith(says), "%s: stderr %r, expected one line %r" % (bad, r.stderr, says))
    r = run([CHAIN, "--check", "--set", "chain.stiffness=200", "--set", "stage.wave.steps=50", "--set", "stage[0].coupled=true"])
    check(r.returncode == 0, "good overrides at --check: exit %d: %s" % (r.returncode, r.stderr))
    r = run([CHAIN, "--set"])
    check(r.returncode == 2 and "--set needs a value" in r.stderr, "--set without a value: %s" % r.stderr)

    # A run with overrides records and runs the effective scene.
    a = os.path.join(tmp, "a")
    r = run([CHAIN, "--set", "chain.stiffness=150", "--set", "stage.wave.steps=120", "--run-dir", a])
    check(r.returncode == 0, "run with --set: exit %d: %s" % (r.returncode, r.stderr[-2000:]))
    text = open(os.path.join(a, "scene.toml")).read() if os.path.exists(os.path.join(a, "scene.toml")) else ""
    check(text.startswith("# Effective scene: %s (" % os.path.realpath(CHAIN)), "header names the scene: %r" % text[:200])
    check("#   --set chain.stiffness=150\n#   --set stage.wave.steps=120\n" in text, "header lists the overrides")
    check("\nstiffness = 150\n" in text and "\nsteps = 120\n" in text, "the effective values are in scene.toml")
    hist = os.path.join(a, "history_0_wave.csv")
    rows = open(hist).read().strip().split("\n") if os.path.exists(hist) else []
    check(len(rows) == 121 and rows[-1].split(",")[0] == "119", "the run made 120 steps (0..119): last row %r" %
          (rows[-1][:40] if rows else None))
    # The same values from a scene file: the same history.
    edited = os.path.join(tmp, "edited.toml")
    src = open(CHAIN).read().replace("stiffness = 100.0", "stiffness = 150.0").replace("steps = 400", "steps = 120")
    check(src != open(CHAIN).read(), "the test edit applies")
    open(edited, "w").write(src)
    b = os.path.join(tmp, "b")
    r = run([edited, "--run-dir", b])
    check(r.returncode == 0, "run of the edited scene: exit %d" % r.returncode)
    for f in ("history_0_wave.csv", "chain_dem.csv", "chain_continuum.csv"):
        pa, pb = os.path.join(a, f), os.path.join(b, f)
        check(os.path.exists(pa) and os.path.exists(pb) and open(pa, "rb").read() == open(pb, "rb").read(),
              "%s: --set and the edited file differ" % f)

    r = run(["--resume", a, "--set", "chain.stiffness=1"])
    check(r.returncode == 2 and "--set is not available" in r.stderr, "--resume with --set: exit %d %s" %
          (r.returncode, r.stderr))

    # --seeds with --set: the ensemble runs the effective scene with each seed. (Its table step
    # needs a footing, so the exit code is not checked; the runs are.)
    ens = os.path.join(tmp, "ens")
    r = run([CHAIN, "--seeds", "2", "--set", "chain.stiffness=150", "--set", "stage.wave.steps=60", "--run-dir", ens],
            timeout=90)
    for k in (1, 2):
        d = os.path.join(ens, "seed-%d" % k)
        sc = open(os.path.join(d, "scene.toml")).read() if os.path.exists(os.path.join(d, "scene.toml")) else ""
        check(os.path.exists(os.path.join(d, "summary.json")), "seed %d: no finished run (%s)" % (k, r.stderr[-1500:]))
        check("\nstiffness = 150\n" in sc and "\nseed = %d\n" % k in sc and "traffic_log = false" in sc,
              "seed %d: scene without the override, its seed or traffic_log = false" % k)
    check(not os.path.exists(os.path.join(ens, "seed-1", "traffic.lcmlog")), "an ensemble run recorded traffic")
finally:
    if fails:
        print("FAIL (kept %s):\n  %s" % (tmp, "\n  ".join(fails)))
    else:
        shutil.rmtree(tmp, ignore_errors=True)
if fails:
    sys.exit(1)
print("run_set: all checks passed")

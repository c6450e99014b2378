#!/usr/bin/python3
"""ctest studies_overrides: the studies express their variants as launch/run --set overrides and
never write scene text. With the build's coordinator (DEMFDM_BUILD) and a stand-in for launch/run
that records its arguments and writes the effective scene a run records (no simulator):
- scenes/accuracy_footing_box.toml differs from scenes/accuracy_footing.toml only as its header
  says (no continuum or coupling, box of walls, replication 2 x 2 x 4, gravity stage "equilibrium",
  nothing coupled), so seed k is the same REV in both;
- overrides.py: quiet_traffic, values_text, ran (an effective scene; an edited copy of the scene
  as a study wrote it before overrides; other values);
- the accuracy study: `plan` checks every run (full with 3 seeds, and --quick); `run --only scheme
  dem_only` launches every run as `launch/run SCENE --set ...` on the shipped scenes (the
  DEM-only reference on accuracy_footing_box.toml), writes no scene text, records the runs in
  plan.json; a second pass launches nothing; a run folder of an earlier study whose scene.toml is
  an edited copy of the scene counts as that run; a folder of the same name with other values
  stops the study (exit 2); a setting the coordinator refuses stops it before anything runs;
- the convergence study: `list --check` of every part; `run --parts box --quick --seeds 2` runs
  seed k as `launch/run SCENE --set ... --set run.seed=k` (the DEM arm on accuracy_footing_box.toml),
  a second pass keeps the finished seeds;
- `launch/study ucs --check`, `stability --check` and `paper --check --seeds 2` list their runs
  as launch/run commands with --set and check them, exit 0.
Usage: check_studies.py SOURCE_ROOT   (environment: DEMFDM_BUILD)
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib

sys.dont_write_bytecode = True
ROOT = os.path.abspath(sys.argv[1])
PY = os.path.join(ROOT, "launch", "py")
sys.path.insert(0, PY)
import overrides  # noqa: E402
import branching  # noqa: E402

fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


LAUNCHER = r"""#!/usr/bin/python3
# Stand-in for launch/run: "SCENE --set=K=V ... --no-build --run-dir DIR [--from CK]". Appends its
# arguments (one JSON line) to $FAKE_LOG, writes the effective scene as DIR/scene.toml (as
# launch/run does with --set) and a finished summary.
import json, os, subprocess, sys
a = sys.argv[1:]
open(os.environ["FAKE_LOG"], "a").write(json.dumps(a) + "\n")
d = a[a.index("--run-dir") + 1]
os.makedirs(d)
sets = [x for x in a if x.startswith("--set=")]
eff = subprocess.run([os.environ["FAKE_COORD"], a[0], "--print-effective"] + sets, capture_output=True, text=True)
if eff.returncode != 0:
    print(eff.stderr)
    sys.exit(2)
open(os.path.join(d, "scene.toml"), "w").write(eff.stdout)
json.dump({"totals": {"steps": 1, "wall_s": 0.1, "nodes": {}}}, open(os.path.join(d, "summary.json"), "w"))
open(os.path.join(d, "summary.txt"), "w").write("total: 1 coupling steps in 0.1 s\n")
"""


def calls(log):
    return [json.loads(x) for x in open(log)] if os.path.exists(log) else []


def tables(path, sets=()):
    return tomllib.loads(overrides.effective(path, sets))


def test_box_scene():
    coupled = tables(os.path.join(ROOT, "scenes", "accuracy_footing.toml"))
    box = tables(os.path.join(ROOT, "scenes", "accuracy_footing_box.toml"))
    for k in ("continuum", "coupling"):
        check(k not in box, "the box scene has [%s]" % k)
        coupled.pop(k, None)
    check(box["dem"]["specimen"]["box"] == "walls" and box["dem"]["specimen"]["replicate"] == [2, 2, 4],
          "box scene: box of walls, replication 2 x 2 x 4")
    coupled["dem"]["specimen"]["box"] = "walls"
    coupled["dem"]["specimen"]["replicate"] = [2, 2, 4]
    for st in coupled["stage"]:
        st["coupled"] = False
        if st["name"] == "gravity":
            st["action"] = "equilibrium"
    check(box == coupled, "the box scene differs from the coupled one in more than its header says")


def test_overrides(tmp):
    scene = os.path.join(ROOT, "scenes", "accuracy_footing.toml")
    check(overrides.quiet_traffic(scene, ["a.b=1"]) == ["a.b=1", "output.traffic_log=false"], "quiet_traffic adds")
    check(overrides.quiet_traffic(scene, ["output.traffic_log=true"]) == ["output.traffic_log=true"],
          "quiet_traffic keeps an override's traffic_log")
    own = os.path.join(tmp, "own.toml")
    open(own, "w").write(open(scene).read() + "\n[output]\ntraffic_log = true\n")
    check(overrides.quiet_traffic(own, ["a.b=1"]) == ["a.b=1"], "quiet_traffic keeps a scene's own traffic_log")
    sets = ["stage.penetrate.damping=0.3", "run.seed=2", "output.traffic_log=false"]
    eff = overrides.effective(scene, sets)
    check(eff.startswith(overrides.EFFECTIVE_HEADER) and not overrides.values_text(eff).startswith("#"),
          "values_text drops the header")
    run = os.path.join(tmp, "r1")
    os.makedirs(run)
    open(os.path.join(run, "scene.toml"), "w").write(eff)
    check(overrides.ran(run, scene, sets), "ran: its own effective scene")
    check(not overrides.ran(run, scene, sets[:1] + ["run.seed=3"] + sets[2:]), "ran: another seed")
    # As a study wrote it before overrides: the scene text with the lines edited.
    text = open(scene).read().replace("seed = 1", "seed = 2").replace("depth_ratio = 0.15", "depth_ratio = 0.15\ndamping = 0.3")
    open(os.path.join(run, "scene.toml"), "w").write(text + "\n[output]\ntraffic_log = false\n")
    check(overrides.ran(run, scene, sets), "ran: an edited copy of the scene with the same values")
    check(overrides.fingerprint(scene, sets) == overrides.digest(overrides.run_values(run)), "fingerprint of a run")


def test_accuracy(tmp, env):
    study_py = os.path.join(PY, "accuracy_study.py")
    for extra in (["--seeds", "3"], ["--quick"]):
        r = subprocess.run([sys.executable, study_py, "plan"] + extra, capture_output=True, text=True, env=env)
        check(r.returncode == 0 and "distinct runs (each checked by the coordinator)" in r.stdout,
              "accuracy plan %s: %d %s" % (extra, r.returncode, r.stderr[-500:]))
        check("launch/run scenes/accuracy_footing.toml --set=" in r.stdout and "launch/run scenes/ucs_sbm_s1.5.toml --set="
              in r.stdout, "accuracy plan %s lists launch/run commands with --set" % extra)
        check(("launch/run scenes/accuracy_footing_box.toml --set=" in r.stdout) == ("--quick" not in extra),
              "accuracy plan %s: the DEM-only runs on the box scene" % extra)
    study = os.path.join(tmp, "acc")
    log = os.path.join(tmp, "acc.calls")
    launcher = os.path.join(tmp, "fake_run")
    envl = dict(env, FAKE_LOG=log)
    cmd = [sys.executable, study_py, "run", study, "--only", "scheme", "dem_only", "--launcher", launcher]
    r = subprocess.run(cmd, capture_output=True, text=True, env=envl)
    check(r.returncode == 0, "accuracy run: %d %s" % (r.returncode, r.stderr[-1500:]))
    got = calls(log)
    scenes = sorted(os.path.basename(c[0]) for c in got)
    check(len(got) == 4, "accuracy run: 4 runs (scheme serial, parallel; dem_only box, coupled): %s" % scenes)
    check(scenes.count("accuracy_footing_box.toml") == 1, "the DEM-only run is on the box scene: %s" % scenes)
    for c in got:
        check(os.path.dirname(c[0]) == os.path.join(ROOT, "scenes") and all(
            x.startswith("--set=") for x in c[1:c.index("--no-build")]), "a run is the shipped scene with --set: %s" % c)
        check("--set=output.traffic_log=false" in c, "no traffic log: %s" % c)
    box = [c for c in got if c[0].endswith("_box.toml")]
    check(box and "--set=dem.specimen.scale=2" in box[0] and not any("continuum" in x for x in box[0]),
          "the DEM-only run: scale 2, no continuum keys: %s" % box)
    check(not [f for f in os.listdir(study) if f.endswith(".toml")], "the study wrote scene text")
    plan = json.load(open(os.path.join(study, "plan.json")))
    check(len(plan.get("runs", {})) == 4 and all(v["set"] for v in plan["runs"].values()), "plan.json runs: %s" % plan)
    # Second pass: nothing runs.
    os.remove(log)
    r = subprocess.run(cmd, capture_output=True, text=True, env=envl)
    check(r.returncode == 0 and not calls(log), "accuracy second pass ran %s: %s" % (calls(log), r.stderr[-500:]))
    # A run folder of a study written before overrides (an edited scene copy) counts as that run.
    r = subprocess.run([sys.executable, study_py, "plan", study, "--only", "interval"],
                       capture_output=True, text=True, env=env)
    name = "footing_interval_5"
    check(r.returncode == 0 and ("to run: %s:" % name) in r.stdout, "plan before the old folder: %s" % r.stdout)
    old = os.path.join(study, name)
    os.makedirs(old)
    text = open(os.path.join(ROOT, "scenes", "accuracy_footing.toml")).read()
    text = text.replace("interval = 1", "interval = 5") + "\n[output]\ntraffic_log = false\n"
    open(os.path.join(old, "scene.toml"), "w").write(text)
    for f, s in (("summary.json", "{}"), ("summary.txt", "stages:\n")):
        open(os.path.join(old, f), "w").write(s)
    r = subprocess.run([sys.executable, study_py, "plan", study, "--only", "interval"],
                       capture_output=True, text=True, env=env)
    check(r.returncode == 0 and ("finished: %s:" % name) in r.stdout, "an old-style run folder is its run: %s" % r.stdout)
    # The same name with other values: the study stops.
    open(os.path.join(old, "scene.toml"), "w").write(text.replace("interval = 5", "interval = 4"))
    r = subprocess.run([sys.executable, study_py, "plan", study, "--only", "interval"],
                       capture_output=True, text=True, env=env)
    check(r.returncode == 2 and "ran other values" in r.stderr, "a run folder with other values: %d %s" % (
        r.returncode, r.stderr))
    shutil.rmtree(old)
    # A setting the coordinator refuses stops the study before anything runs (here: a scene whose
    # replication no longer fits its mesh, through DEMFDM_ROOT pointing at a copy of the sources'
    # scenes with a broken footing scene).
    fake_root = os.path.join(tmp, "root")
    os.makedirs(os.path.join(fake_root, "scenes"))
    for s in ("accuracy_footing.toml", "accuracy_footing_box.toml", "ucs_sbm_s1.5.toml"):
        shutil.copy(os.path.join(ROOT, "scenes", s), os.path.join(fake_root, "scenes", s))
    with open(os.path.join(fake_root, "scenes", "accuracy_footing.toml"), "a") as f:
        f.write("\n[[stage]]\nname = \"x\"\naction = \"nosuch\"\nsteps = 1\n")
    os.remove(log) if os.path.exists(log) else None
    r = subprocess.run([sys.executable, study_py, "run", os.path.join(tmp, "acc2"), "--quick", "--only", "scheme",
                        "--launcher", launcher], capture_output=True, text=True, env=dict(envl, DEMFDM_ROOT=fake_root))
    check(r.returncode == 2 and "nosuch" in r.stderr and not calls(log) and not os.path.exists(os.path.join(tmp, "acc2")),
          "a refused setting: exit 2 before anything runs: %d %s" % (r.returncode, r.stderr[-500:]))


def test_converge(tmp, env):
    study_py = os.path.join(PY, "converge_study.py")
    r = subprocess.run([sys.executable, study_py, "list", "--parts", "rate", "dt", "damping", "box", "wide", "--seeds", "2",
                        "--check"], capture_output=True, text=True, env=env)
    check(r.returncode == 0 and "0 refused" in r.stderr and "launch/run scenes/accuracy_footing_box.toml" in r.stdout,
          "converge list --check: %d %s %s" % (r.returncode, r.stdout[-500:], r.stderr[-500:]))
    wide = [x for x in r.stdout.split("\n") if x.startswith("wide_")]
    check(len(wide) == 4 and all("dem.footing.diameter=1.2e-3" in x and "inertial_number=7.5e-4" in x for x in wide)
          and sum("[3, 3, 4]" in x for x in wide) == 1, "converge list: the wide part's four arms: %s" % wide)
    study = os.path.join(tmp, "conv")
    log = os.path.join(tmp, "conv.calls")
    cmd = [sys.executable, study_py, "run", study, "--parts", "box", "--quick", "--seeds", "2",
           "--launcher", os.path.join(tmp, "fake_run")]
    envl = dict(env, FAKE_LOG=log)
    r = subprocess.run(cmd, capture_output=True, text=True, env=envl)
    check(r.returncode == 0, "converge run: %d %s" % (r.returncode, r.stderr[-1500:]))
    got = calls(log)
    check(len(got) == 6, "converge run: 3 arms x 2 seeds, got %d runs" % len(got))
    for c in got:
        run_dir = c[c.index("--run-dir") + 1]
        arm, seed = run_dir.split(os.sep)[-2:]
        want_scene = "accuracy_footing_box.toml" if arm.startswith("box_dem_") else "accuracy_footing.toml"
        check(os.path.basename(c[0]) == want_scene, "%s: scene %s" % (arm, c[0]))
        check("--set=run.seed=%s" % seed.split("-")[1] in c and "--set=stage.penetrate.depth_ratio=0.05" in c,
              "%s %s: seed and --quick as overrides: %s" % (arm, seed, c))
        eff = open(os.path.join(run_dir, "scene.toml")).read()
        check(("[continuum]" in eff) != arm.startswith("box_dem_"), "%s: continuum in its effective scene" % arm)
    check(not [f for _, _, fs in os.walk(study) for f in fs if f.endswith(".toml") and f != "scene.toml"],
          "the convergence study wrote scene text")
    os.remove(log)
    r = subprocess.run(cmd, capture_output=True, text=True, env=envl)
    check(r.returncode == 0 and not calls(log) and r.stderr.count(": kept (exit 0)") == 6,
          "converge second pass: %s %s" % (calls(log), r.stderr[-500:]))


def test_shell_studies(env):
    for name, args in (("ucs", ["--check", "--seeds", "2"]), ("stability", ["--check"]),
                       ("paper", ["--check", "--seeds", "2", "--only", "100g_sbm 200g_sbm"])):
        r = subprocess.run(["bash", os.path.join(ROOT, "launch", "studies", name + ".sh")] + args,
                           capture_output=True, text=True, env=env, timeout=240)
        check(r.returncode == 0 and "0 refused" in r.stderr, "%s --check: %d %s" % (name, r.returncode, r.stderr[-800:]))
        lines = [x for x in r.stdout.split("\n") if x]
        check(lines and all("launch/run " in x for x in lines), "%s --check lists launch/run commands: %s" % (name, lines))
        check(any("--set" in x for x in lines), "%s --check: runs with overrides" % name)


def main():
    coord = branching.coordinator_command()[0]
    if not os.access(coord, os.X_OK):
        print("FAIL: no coordinator at %s (DEMFDM_BUILD)" % coord)
        return 1
    tmp = tempfile.mkdtemp(prefix="demfdm-studies-")
    env = dict(os.environ, DEMFDM_ROOT=ROOT, DEMFDM_BUILD=os.path.dirname(os.path.dirname(coord)), FAKE_COORD=coord)
    before = sorted(os.listdir(os.path.join(ROOT, "scenes")))
    try:
        launcher = os.path.join(tmp, "fake_run")
        open(launcher, "w").write(LAUNCHER)
        os.chmod(launcher, 0o755)
        test_box_scene()
        test_overrides(tmp)
        test_accuracy(tmp, env)
        test_converge(tmp, env)
        test_shell_studies(env)
        check(sorted(os.listdir(os.path.join(ROOT, "scenes"))) == before, "a study wrote into scenes/")
    finally:
        if fails:
            print("FAIL (kept %s):\n  %s" % (tmp, "\n  ".join(fails)))
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    if fails:
        return 1
    print("studies_overrides: all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

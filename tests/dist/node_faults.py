#!/usr/bin/python3
"""Faults with the DEM on MPI ranks, through launch/run (issue 17 item 3): on
scenes/footing_small.toml with dem.ranks = 2,

1. the blow-up guard: the top ball kicked out of the block at the gravity stage (dem.kick, on the
   ranks' parts) stops the run with exit code 3 and the same report (blowup_dem.txt, byte for
   byte) as on one process: the ranks find it and the whole World reports it; the same with the escape test off
   and the kinetic-energy jump test finding it (rank 0's test, its verdict broadcast);
2. a dead rank: rank 1 of the DEM killed with SIGKILL in the penetration ends the run with exit
   code 3 within 5 s, launch/run naming the DEM and the coordinator naming node 'dem';
3. never losing a ranked run: checkpoints inside the penetration, rank 1 killed, `launch/run
   --resume` (the ranks load their parts from the checkpoint, no whole World on rank 0): every
   CSV file the bytes of the one-process run.

Usage: node_faults.py SOURCE_DIR BUILD_DIR WORK_DIR
"""
import os
import shutil
import signal
import subprocess
import sys
import time

src, build, work = sys.argv[1:4]
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)
env = dict(os.environ, DEMFDM_BUILD=build)
failures = []


def launch(name, sets):
    args = ["/bin/bash", os.path.join(src, "launch/run"), os.path.join(src, "scenes/footing_small.toml"), "--no-build",
            "--run-dir", os.path.join(work, name), "--set", "output.traffic_log=false"]
    for s in sets:
        args += ["--set", s]
    return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


# 1. The guard: the kicked ball leaves the block (escape test), and, with no escape test and the
# energy-jump factor at 5, the kinetic energy jumps (rank 0's test decides on the ranks).
for case, sets, words in (("kick", [], b"left the DEM domain"),
                          ("jump", ["dem.escape_margin=0", "run.guard_energy_jump=5"], b"kinetic energy jumped")):
    reports = {}
    for ranks in (1, 2):
        name = "%s_ranks%d" % (case, ranks)
        p = launch(name, ["dem.ranks=%d" % ranks, "dem.kick=[0.0, 0.0, 200.0]"] + sets)
        out, _ = p.communicate(timeout=300)
        path = os.path.join(work, name, "blowup_dem.txt")
        print("%s: exit code %d, report %s" % (name, p.returncode, "written" if os.path.exists(path) else "missing"))
        if p.returncode != 3:
            failures.append("%s: exit code %d, expected 3\n%s" % (name, p.returncode, out[-3000:]))
        if not os.path.exists(path):
            failures.append("%s: no blowup_dem.txt" % name)
            continue
        if ranks == 2:  # the kick on the ranks' parts (DistDem's kick_highest_ball), not on an assembled World
            log = open(os.path.join(work, name, "dem.log")).read()
            if "on the ranks' parts" not in log[log.find("dem: kick:"):][:300]:
                failures.append("%s: the kick was not given on the ranks' parts" % name)
        reports[ranks] = open(path, "rb").read()
        if words not in reports[ranks]:
            failures.append("%s: the report does not say '%s'" % (name, words.decode()))
    if len(reports) == 2:
        if reports[1] != reports[2]:
            failures.append("%s: the blow-up report on 2 ranks differs from one process's" % case)
        else:
            print("%s: blow-up report on 2 ranks: the same %d bytes as on one process (%s)" %
                  (case, len(reports[2]), reports[2].split(b"\n")[1].decode()[:120]))


# 2. A dead rank.
def rank_pid(run_dir, rank):
    """The pid of the DEM's rank `rank` of the run in `run_dir` (its environment says its rank)."""
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmd = open("/proc/%s/cmdline" % pid, "rb").read()
            if b"dem_node" not in cmd or ("--run-dir=" + run_dir).encode() not in cmd:
                continue
            envs = open("/proc/%s/environ" % pid, "rb").read().split(b"\0")
        except OSError:
            continue
        if ("OMPI_COMM_WORLD_RANK=%d" % rank).encode() in envs:
            return int(pid)
    return None


name = "dead_rank"
run_dir = os.path.join(work, name)
p = launch(name, ["dem.ranks=2", "stage.penetrate.depth_ratio=1.0", "stage.penetrate.steps=400000"])
log = os.path.join(run_dir, "dem.log")
deadline = time.time() + 120
while time.time() < deadline and p.poll() is None:
    if os.path.exists(log) and "stage 5 'penetrate' (penetrate) begins" in open(log).read():
        break
    time.sleep(0.1)
time.sleep(1.0)
pid = rank_pid(os.path.realpath(run_dir), 1)
if p.poll() is not None or pid is None:
    failures.append("dead rank: the run ended before the kill or rank 1 was not found (pid %s)" % pid)
    p.kill()
else:
    t0 = time.time()
    os.kill(pid, signal.SIGKILL)
    try:
        out, _ = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        out, _ = p.communicate()
    took = time.time() - t0
    coord = open(os.path.join(run_dir, "coordinator.log")).read()
    print("rank 1 of the DEM killed in the penetration: the run ended with code %d after %.2f s" % (p.returncode, took))
    print("  " + "\n  ".join(l for l in out.split("\n") if "launch/run: dem" in l or "node 'dem'" in l))
    if p.returncode != 3:
        failures.append("dead rank: exit code %d, expected 3\n%s" % (p.returncode, out[-3000:]))
    if took >= 5.0:
        failures.append("dead rank: the run ended %.2f s after the kill, not within 5 s" % took)
    if "launch/run: dem (pid" not in out:
        failures.append("dead rank: launch/run does not name the DEM\n" + out[-2000:])
    if "node 'dem'" not in coord:
        failures.append("dead rank: the coordinator does not name node 'dem'\n" + coord[-2000:])

# 3. Never lose a ranked run: checkpoints inside the penetration every 0.2 s of wall time, rank 1
# killed once two exist, `launch/run --resume`: the results of one process, byte for byte.
def wait_run(p, name, timeout=300):
    out, _ = p.communicate(timeout=timeout)
    if p.returncode != 0:
        failures.append("%s: exit code %d\n%s" % (name, p.returncode, out[-3000:]))
    return out


def inside(run_dir):
    d = os.path.join(run_dir, "checkpoints")
    if not os.path.isdir(d):
        return []
    return [n for n in os.listdir(d) if n.startswith("penetrate-") and not n.endswith("-end") and
            os.path.exists(os.path.join(d, n, "manifest.txt"))]


wait_run(launch("resume_ref", []), "resume_ref")
name = "resumed"
run_dir = os.path.join(work, name)
p = launch(name, ["dem.ranks=2", "run.checkpoint_every_s=0.2"])
deadline = time.time() + 120
while time.time() < deadline and p.poll() is None and len(inside(run_dir)) < 2:
    time.sleep(0.01)
pid = rank_pid(os.path.realpath(run_dir), 1)
if p.poll() is not None or pid is None or len(inside(run_dir)) < 2:
    failures.append("resume: the run ended before two checkpoints inside the penetration (%s)" % inside(run_dir))
    p.kill()
    p.communicate()
else:
    at_kill = sorted(inside(run_dir))
    os.kill(pid, signal.SIGKILL)
    p.communicate(timeout=60)
    if p.returncode == 0:
        failures.append("resume: the run whose rank 1 was killed exited 0")
    r = subprocess.run(["/bin/bash", os.path.join(src, "launch/run"), "--resume", run_dir, "--no-build"], env=env,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        failures.append("resume: launch/run --resume ended with code %d\n%s" % (r.returncode, r.stdout[-3000:]))
    else:
        ref = os.path.join(work, "resume_ref")
        csvs = sorted(n for n in os.listdir(ref) if n.endswith(".csv"))
        differ = [n for n in csvs if open(os.path.join(ref, n), "rb").read() !=
                  open(os.path.join(run_dir, n), "rb").read() if os.path.exists(os.path.join(run_dir, n))]
        missing = [n for n in csvs if not os.path.exists(os.path.join(run_dir, n))]
        log = open(os.path.join(run_dir, "coordinator.log")).read()
        frm = [l for l in log.split("\n") if "resuming run" in l]
        print("2 ranks killed after checkpoints %s, resumed (%s): %d of %d CSV files the bytes of one process" %
              (at_kill, frm[-1].split(" from ")[-1] if frm else "?", len(csvs) - len(differ) - len(missing),
               len(csvs)))
        if differ or missing:
            failures.append("resume: %s differ, %s missing" % (differ, missing))
        # the resumed ranks loaded their parts from the checkpoint, no whole World on rank 0
        # (DistDem::load_state_file)
        dlog = open(os.path.join(run_dir, "dem.log")).read()
        if "the block loaded from the checkpoint into 2 bricks" not in dlog:
            failures.append("resume: the ranks did not load their parts from the checkpoint")

for f in failures:
    print("FAIL:", f)
sys.exit(1 if failures else 0)

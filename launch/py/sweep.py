#!/usr/bin/python3
"""Parameter sweeps (issue 14 item 4): one scene over the cartesian product of key values, times
generator seeds, into one sweep folder with an index of the runs and their results.

Usage (launch/sweep does the same after building):
  /usr/bin/python3 launch/py/sweep.py SCENE --vary KEY=V1,V2,... [--vary KEY2=...] [--set KEY=VALUE ...]
      [--seeds SPEC] [--jobs J] [--into SWEEP_DIR | --runs-root DIR] [--no-branch] [--check]
  /usr/bin/python3 launch/py/sweep.py --into SWEEP_DIR [--jobs J]     (continue it with its own plan)

KEY is any scene key as launch/run --set takes it (dem.damping, stage.penetrate.inertial_number,
stage[4].steps); the values are TOML values separated by commas at bracket depth 0, so
`--vary dem.specimen.replicate=[1,1,2],[2,2,2]` gives two values. --set fixes keys for every run.
SPEC is N (seeds 1..N), A-B or a comma list (1,4,7-9); each seed sets run.seed. The runs are the
product of the --vary lists (the first --vary varies slowest) times the seeds (fastest), numbered
1, 2, ... in that order. As in ensembles and studies, the runs record no traffic log unless the
scene or an override says traffic_log (--set output.traffic_log=false is added).

Every combination is validated (coordinator SCENE --check --set ...) before any run starts; a bad
one is named with the coordinator's one error line, exit 2. Each run is
`launch/run SCENE --no-build --set ... --run-dir SWEEP_DIR/<k>` (output in SWEEP_DIR/<k>.log), at
most J at once (default 1). A run that differs from a finished run of the sweep only in keys a
saved state allows (later stages, rates, outputs) starts from that run's stage-end checkpoint that
saves the most steps (launch/py/branching.py, checked by the coordinator: launch/run --from);
--no-branch runs every one from scratch.

The sweep folder (new: runs/<date>-<time>-<scene>-sweep/, or --into DIR) holds sweep.json (the
plan), index.csv and index.json (one row per run: run number, the varied keys, seed, run folder,
status, exit code, wall time of launch/run, the result of its summary.json (peak_N, k_e_N_m,
final_N, target_reached; empty for a run without a footing), and branched_from (the checkpoint
it started from, relative to the sweep folder)), rewritten after every run, and the runs. Rerun
with --into on the folder, a sweep runs only what has not finished: a finished run (summary.json,
summary.txt not FAILED) is kept when its scene.toml has the values in effect of its combination
(read through the coordinator; else: error, use a new folder); an unfinished folder is kept as
<k>.incomplete-<i> and rerun.
Exit code: 0 every run finished, 2 bad arguments or a bad combination, 3 a run failed (the others
still run), 130 interrupted (rerun with --into to continue).

Library: split_values(text), parse_vary(text), parse_seeds(spec), plan_runs(vary, seeds, sets).
"""
import argparse
import csv
import datetime
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import branching  # noqa: E402  (finished, branch_source, coordinator_command)
import overrides  # noqa: E402  (set_args, quiet_traffic, check, ran: scene variants as overrides)

ROOT = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
RESULT_KEYS = ("peak_N", "k_e_N_m", "final_N", "target_reached")


class SweepError(Exception):
    """A bad argument or plan: one line, exit 2."""


def split_values(text):
    """Splits a --vary value list on the commas at bracket depth 0 and outside quotes:
    '1,2' -> ['1', '2']; '[1,1,2],[2,2,2]' -> ['[1,1,2]', '[2,2,2]']; '"a,b",c' -> ['"a,b"', 'c']."""
    out, cur, depth, quote = [], "", 0, None
    for ch in text:
        if quote:
            cur += ch
            if ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise SweepError("unbalanced '%s' in '%s'" % (ch, text))
        elif ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
            continue
        cur += ch
    if depth != 0 or quote:
        raise SweepError("unbalanced brackets or quotes in '%s'" % text)
    out.append(cur.strip())
    return out


def parse_vary(text):
    """'KEY=V1,V2' -> (KEY, [V1, V2])."""
    key, eq, values = text.partition("=")
    key = key.strip()
    if not eq or not key:
        raise SweepError("--vary %s: expected KEY=V1,V2,..." % text)
    try:
        vals = split_values(values)
    except SweepError as ex:
        raise SweepError("--vary %s: %s" % (text, ex))
    if any(v == "" for v in vals):
        raise SweepError("--vary %s: an empty value (values are separated by commas)" % text)
    return key, vals


def parse_seeds(spec):
    """N -> 1..N; A-B -> A..B; a comma list of seeds and A-B ranges -> those (sorted, unique)."""
    spec = spec.strip()
    if re.fullmatch(r"\d+", spec):
        if int(spec) < 1:
            raise SweepError("--seeds %s: N must be at least 1" % spec)
        return list(range(1, int(spec) + 1))
    seeds = set()
    for part in spec.split(","):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part.strip())
        if not m or (m.group(2) and int(m.group(2)) < int(m.group(1))):
            raise SweepError("--seeds %s: expected N, A-B or a comma list of seeds and ranges (A <= B)" % spec)
        seeds.update(range(int(m.group(1)), int(m.group(2) or m.group(1)) + 1))
    return sorted(seeds)


def plan_runs(vary, seeds, sets=()):
    """[{run, keys: {key: value}, seed, sets}] for the product of the vary lists ([(key, values)],
    the first slowest) times the seeds (None: the scene's seed), numbered from 1. sets: the
    overrides every run gets first."""
    runs = []
    combos = itertools.product(*[vals for _, vals in vary]) if vary else [()]
    for combo in combos:
        for seed in (seeds or [None]):
            keys = {k: v for (k, _), v in zip(vary, combo)}
            s = list(sets) + ["%s=%s" % kv for kv in keys.items()]
            if seed is not None:
                s.append("run.seed=%d" % seed)
            runs.append({"run": len(runs) + 1, "keys": keys, "seed": seed, "sets": s})
    return runs


def set_args(run):
    return overrides.set_args(run["sets"])


def describe(run):
    parts = ["%s=%s" % kv for kv in run["keys"].items()]
    if run["seed"] is not None:
        parts.append("seed %d" % run["seed"])
    return ", ".join(parts) or "the scene as it is"


def read_result(run_dir):
    """(result values, seed) from a finished run's summary.json."""
    try:
        js = json.load(open(os.path.join(run_dir, "summary.json")))
    except (OSError, ValueError):
        return {}, None
    res = js.get("result") or {}
    return {k: res.get(k) for k in RESULT_KEYS if k in res}, (js.get("run") or {}).get("seed")


def run_wall(run_dir):
    """The coordinator's wall time of a finished run (summary.json totals), or None."""
    try:
        return float(json.load(open(os.path.join(run_dir, "summary.json")))["totals"]["wall_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def branched_from(run_dir, folder):
    """The checkpoint a finished run started from (its summary.txt line "branched from DIR (after
    step N)"), relative to the sweep folder, or None."""
    try:
        m = re.search(r"(?m)^branched from (.*) \(after step \d+\)$", open(os.path.join(run_dir, "summary.txt")).read())
    except OSError:
        return None
    return os.path.relpath(m.group(1), folder) if m else None


class Sweep:
    def __init__(self, folder, plan, runs, launcher, coordinator, branch=True):
        self.folder, self.plan, self.runs = folder, plan, runs
        self.launcher, self.coordinator, self.branch = launcher, coordinator, branch
        self.rows = {}

    def run_dir(self, run):
        return os.path.join(self.folder, str(run["run"]))

    def row(self, run):
        return self.rows.setdefault(run["run"], {
            "run": run["run"], "keys": dict(run["keys"]), "seed": run["seed"], "run_dir": str(run["run"]),
            "status": "pending", "exit_code": None, "wall_s": None, "peak_N": None, "k_e_N_m": None, "final_N": None,
            "target_reached": None, "branched_from": None})

    def finish_row(self, run, status, rc=None, wall=None):
        r = self.row(run)
        r["status"] = status
        if rc is not None:
            r["exit_code"] = rc
        if wall is not None:
            r["wall_s"] = round(wall, 3)
        if status == "finished":
            res, seed = read_result(self.run_dir(run))
            r.update({k: res.get(k) for k in RESULT_KEYS})
            if r["seed"] is None:
                r["seed"] = seed

    def write_index(self):
        rows = [self.row(run) for run in self.runs]
        keys = [k for k, _ in self.plan["vary"]]
        tmp = os.path.join(self.folder, "index.json.tmp")
        with open(tmp, "w") as f:
            json.dump({"scene": self.plan["scene"], "vary": self.plan["vary"], "set": self.plan["set"],
                       "seeds": self.plan["seeds"], "runs": rows}, f, indent=1)
        os.replace(tmp, os.path.join(self.folder, "index.json"))
        tmp = os.path.join(self.folder, "index.csv.tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["run"] + keys + ["seed", "run_dir", "status", "exit_code", "wall_s"] + list(RESULT_KEYS) +
                       ["branched_from"])
            for r in rows:
                cell = lambda v: "" if v is None else ("true" if v is True else "false" if v is False else v)  # noqa
                w.writerow([r["run"]] + [r["keys"].get(k, "") for k in keys] +
                           [cell(r[c]) for c in ("seed", "run_dir", "status", "exit_code", "wall_s")] +
                           [cell(r[c]) for c in RESULT_KEYS] + [cell(r["branched_from"])])
        os.replace(tmp, os.path.join(self.folder, "index.csv"))

    def finished_dirs(self):
        return [self.run_dir(run) for run in self.runs if self.row(run)["status"] == "finished"]

    def start(self, run):
        cmd = [self.launcher, self.plan["scene"], "--no-build"] + set_args(run) + ["--run-dir", self.run_dir(run)]
        src = None
        if self.branch:
            src = branching.branch_source(self.coordinator + set_args(run), self.plan["scene"], self.finished_dirs())
        if src:
            cmd[3:3] = ["--from", src]
        r = self.row(run)
        r["status"], r["branched_from"] = "running", os.path.relpath(src, self.folder) if src else None
        log = open(os.path.join(self.folder, "%d.log" % run["run"]), "w")
        return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT), log

    def execute(self, pending, jobs):
        """Runs `pending` (plan entries), at most `jobs` at once; returns the exit code."""
        active, failed, done, interrupted = {}, [], 0, False
        queue = list(pending)
        t_all = time.time()
        try:
            while queue or active:
                while queue and len(active) < max(1, jobs):
                    run = queue.pop(0)
                    p, log = self.start(run)
                    active[p.pid] = (run, p, log, time.time())
                    self.write_index()
                pid, status = os.wait()
                if pid not in active:
                    continue
                run, p, log, t0 = active.pop(pid)
                p.returncode = os.waitstatus_to_exitcode(status)
                log.close()
                rc = p.returncode if p.returncode >= 0 else 128 - p.returncode
                wall = time.time() - t0
                done += 1
                ok = rc == 0 and branching.finished(self.run_dir(run))
                if rc == 130:
                    interrupted = True
                    queue.clear()
                    self.finish_row(run, "interrupted", rc, wall)
                    print("sweep: run %d interrupted; starting no other run" % run["run"], file=sys.stderr, flush=True)
                elif ok:
                    self.finish_row(run, "finished", rc, wall)
                    r = self.row(run)
                    res = ", ".join("%s %s" % (k, json.dumps(r[k])) for k in RESULT_KEYS if r[k] is not None)
                    print("sweep: [%d/%d] run %d (%s) done in %.1f s%s%s" % (
                        done, len(pending), run["run"], describe(run), wall,
                        "; branched from " + r["branched_from"] if r["branched_from"] else "",
                        "; " + res if res else ""), file=sys.stderr, flush=True)
                else:
                    self.finish_row(run, "failed", rc, wall)
                    failed.append(run)
                    tail = []
                    try:
                        tail = open(os.path.join(self.folder, "%d.log" % run["run"]), errors="replace").read() \
                            .rstrip("\n").split("\n")[-10:]
                    except OSError:
                        pass
                    print("sweep: [%d/%d] run %d (%s) FAILED (exit code %d) after %.1f s; last lines of %s:\n    %s" % (
                        done, len(pending), run["run"], describe(run), rc, wall,
                        os.path.join(self.folder, "%d.log" % run["run"]), "\n    ".join(tail)),
                        file=sys.stderr, flush=True)
                self.write_index()
        except KeyboardInterrupt:
            print("sweep: interrupted; stopping %d run(s); continue with launch/sweep --into %s" %
                  (len(active), self.folder), file=sys.stderr)
            branching.stop_runs(list(active.values()))
            for run, p, log, t0 in active.values():
                if p.returncode == 0 and branching.finished(self.run_dir(run)):  # it finished meanwhile
                    self.finish_row(run, "finished", 0, time.time() - t0)
                else:
                    self.finish_row(run, "interrupted", 130, time.time() - t0)
            self.write_index()
            return 130
        if interrupted:
            print("sweep: interrupted; continue with launch/sweep --into %s" % self.folder, file=sys.stderr)
            return 130
        print("sweep: %d run(s) in %.1f s, %d failed; index %s" % (
            len(pending), time.time() - t_all, len(failed), os.path.join(self.folder, "index.csv")), file=sys.stderr)
        if failed:
            print("sweep: FAILED runs: %s" % ", ".join("%d (%s)" % (r["run"], describe(r)) for r in failed),
                  file=sys.stderr)
            return 3
        return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", nargs="?")
    ap.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--seeds", metavar="SPEC")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--into", metavar="SWEEP_DIR")
    ap.add_argument("--runs-root", default=os.environ.get("DEMFDM_RUNS_ROOT", os.path.join(os.getcwd(), "runs")))
    ap.add_argument("--no-branch", action="store_true")
    ap.add_argument("--check", action="store_true", help="validate every combination, run nothing")
    ap.add_argument("--no-build", action="store_true", help=argparse.SUPPRESS)  # (launch/sweep's option)
    ap.add_argument("--launcher", help=argparse.SUPPRESS)  # tests: a stand-in for launch/run
    a = ap.parse_args(argv)
    try:
        return sweep(a)
    except SweepError as ex:
        print("sweep: %s" % ex, file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # before any run started
        print("sweep: interrupted", file=sys.stderr)
        return 130


def sweep(a):
    if a.jobs < 1:
        raise SweepError("--jobs must be at least 1")
    stored = None
    if a.into and os.path.isfile(os.path.join(a.into, "sweep.json")):
        stored = json.load(open(os.path.join(a.into, "sweep.json")))
    if a.scene is None and not a.vary and not a.set and a.seeds is None:
        if stored is None:
            raise SweepError("expected SCENE --vary KEY=V1,V2,... (or --into SWEEP_DIR of an earlier sweep)")
        plan = stored
    else:
        if a.scene is None:
            raise SweepError("expected a scene: launch/sweep SCENE --vary KEY=V1,V2,...")
        if not os.path.isfile(a.scene):
            raise SweepError("%s: cannot read scene file" % a.scene)
        if not a.vary and a.seeds is None:
            raise SweepError("nothing to sweep: give --vary KEY=V1,V2,... and/or --seeds SPEC")
        vary = [parse_vary(v) for v in a.vary]
        keys = [k for k, _ in vary]
        for k in keys:
            if keys.count(k) > 1:
                raise SweepError("--vary %s is given twice" % k)
        seeds = parse_seeds(a.seeds) if a.seeds is not None else None
        if seeds and "run.seed" in keys:
            raise SweepError("--vary run.seed and --seeds: give the seeds once")
        for s in a.set:
            if "=" in s and s.split("=", 1)[0].strip() in keys:
                raise SweepError("--set %s: the key is also varied" % s)
        sets = list(a.set)
        if "output.traffic_log" not in keys:
            sets = overrides.quiet_traffic(a.scene, sets)
        plan = {"scene": os.path.realpath(a.scene), "vary": [[k, v] for k, v in vary], "set": sets, "seeds": seeds}
        if stored is not None and stored != plan:
            diff = [k for k in ("scene", "vary", "set", "seeds") if stored.get(k) != plan.get(k)]
            raise SweepError("%s holds another sweep (its %s differ%s: %s); use a new folder, or continue it with "
                             "launch/sweep --into %s alone" % (a.into, " and ".join(diff), "s" if len(diff) == 1 else "",
                                                               "; ".join("%s %s" % (k, json.dumps(stored.get(k)))
                                                                         for k in diff), a.into))
    runs = plan_runs([(k, v) for k, v in plan["vary"]], plan["seeds"], plan["set"])
    coordinator = branching.coordinator_command()
    launcher = a.launcher or os.path.join(ROOT, "launch", "run")
    if not os.access(coordinator[0], os.X_OK):
        raise SweepError("%s not built" % coordinator[0])

    # Every combination is valid before anything starts.
    for run in runs:
        ok, msg = overrides.check(plan["scene"], run["sets"], coordinator)
        if not ok:
            raise SweepError("run %d (%s): %s" % (run["run"], describe(run), msg))
    print("sweep: %d combination(s) valid (%s)" % (len(runs), plan["scene"]), file=sys.stderr)
    if a.check:
        return 0

    if a.into:
        folder = os.path.realpath(a.into)
    else:
        name = os.path.splitext(os.path.basename(plan["scene"]))[0]
        folder = os.path.join(os.path.realpath(a.runs_root),
                              "%s-%s-sweep" % (datetime.datetime.now().strftime("%Y%m%d-%H%M%S"), name))
        if os.path.exists(folder):
            raise SweepError("sweep folder %s exists; an earlier one is never overwritten" % folder)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as ex:
        raise SweepError("cannot create the sweep folder %s: %s" % (folder, ex.strerror))
    sw = Sweep(folder, plan, runs, launcher, coordinator, branch=not a.no_branch)
    # What an earlier pass left: finished runs are kept (when they ran this combination), the rest
    # runs again.
    old = {}
    if os.path.isfile(os.path.join(folder, "index.json")):
        try:
            old = {r["run"]: r for r in json.load(open(os.path.join(folder, "index.json"))).get("runs", [])}
        except (OSError, ValueError, KeyError, TypeError):
            old = {}
    pending, kept = [], []
    for run in runs:
        d = sw.run_dir(run)
        if os.path.isdir(d) and branching.finished(d):
            try:
                same = overrides.ran(d, plan["scene"], run["sets"], coordinator)
            except ValueError:
                same = False
            if not same:
                raise SweepError("%s was run from another scene or other values than run %d (%s); use a new sweep "
                                 "folder" % (d, run["run"], describe(run)))
            # The earlier pass's row when it saw the run finish; else the run's own wall time.
            row = sw.row(run)
            prev = old.get(run["run"], {})
            if prev.get("status") != "finished":
                prev = {"exit_code": 0, "wall_s": run_wall(d), "branched_from": branched_from(d, folder)}
            row["branched_from"] = prev.get("branched_from")
            sw.finish_row(run, "finished", prev.get("exit_code", 0), prev.get("wall_s"))
            kept.append(run)
        else:
            if os.path.exists(d):
                i = 1
                while os.path.exists("%s.incomplete-%d" % (d, i)):
                    i += 1
                os.rename(d, "%s.incomplete-%d" % (d, i))
                print("sweep: run %d: unfinished folder of an earlier pass kept as %s.incomplete-%d; running it again"
                      % (run["run"], d, i), file=sys.stderr)
            pending.append(run)
    with open(os.path.join(folder, "sweep.json"), "w") as f:
        json.dump(plan, f, indent=1)
    sw.write_index()
    print("sweep: %s: %d run(s), %d finished before, %d to run" % (folder, len(runs), len(kept), len(pending)),
          file=sys.stderr, flush=True)
    if not pending:
        print("sweep: nothing to run; index %s" % os.path.join(folder, "index.csv"), file=sys.stderr)
        return 0

    def stop(signum, frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, stop)  # SIGTERM stops the runs as Ctrl-C does
    return sw.execute(pending, a.jobs)


if __name__ == "__main__":
    sys.exit(main())

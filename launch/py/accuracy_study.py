#!/usr/bin/python3
"""Accuracy-cost study (launch/study accuracy; docs/accuracy-study.md).

Usage:
  /usr/bin/python3 launch/py/accuracy_study.py run STUDY_DIR [--quick] [--seeds N] [--only KNOB ...] [--no-branch]
  /usr/bin/python3 launch/py/accuracy_study.py plan [STUDY_DIR] [--quick] [--seeds N] [--only KNOB ...]
  /usr/bin/python3 launch/py/accuracy_study.py table STUDY_DIR
  /usr/bin/python3 launch/py/accuracy_study.py list

run: every setting of each knob is a scene file and overrides (launch/run --set): a setting of
the footing problem is scenes/accuracy_footing.toml with some keys set (the DEM-only reference of
the dem_only knob: scenes/accuracy_footing_box.toml, the same problem without its continuum), one
of the UCS problem scenes/ucs_sbm_s1.5.toml. Settings with the same values in effect (the
coordinator's effective scene) are one run. Every run is checked by the coordinator before any
starts (a bad one: its error line, exit 2); then each distinct run goes through launch/run SCENE
--set ... (sequentially, one thread per node) into STUDY_DIR/<run>/, which records its effective
scene as scene.toml, and the table and the figure are written. Rerun into the same folder, a
study runs only what has not run (a run is known by its values in effect, also in folders written
before the studies used overrides). plan: the runs and their launch/run commands, each checked by
the coordinator, and with STUDY_DIR which have run; nothing starts. table: rebuilds
accuracy_table.{csv,md} and accuracy_pareto.png from the run folders of STUDY_DIR (plan.json).
Needs DEMFDM_ROOT (and DEMFDM_BUILD for launch/run and the coordinator).

For each run: wall time of the run (summary.json totals, the coordinator's clock), and the error
against the most accurate setting of its knob: peak load (UCS: the UCS), initial stiffness
(paper_figures.initial_stiffness; UCS: E50), and the whole curve's normalised difference
(compare_curves.curve_difference: RMS of the load difference over the common displacement range
/ reference peak; UCS: stress over strain).
"""
import argparse
import csv
import json
import os
import re
import shlex
import subprocess
import sys
import time

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compare_curves  # noqa: E402  (the normalised curve difference)
import paper_figures  # noqa: E402  (initial-stiffness rule and the footing curve of a run folder)
import branching  # noqa: E402  (which saved state a run may start from)
import overrides  # noqa: E402  (scene variants as launch/run --set overrides)

FOOTING_SCENE = "scenes/accuracy_footing.toml"
# The footing problem with DEM everywhere (no continuum, a box of walls; its header lists the
# differences): an override sets keys, it cannot remove the [continuum] and [coupling] sections.
BOX_SCENE = "scenes/accuracy_footing_box.toml"
UCS_SCENE = "scenes/ucs_sbm_s1.5.toml"
BASE_SCENES = {"footing": FOOTING_SCENE, "ucs": UCS_SCENE}


def setting(label, *sets, scene=None):
    """A knob setting: (label, overrides, scene file relative to the repository; None: the
    problem's base scene)."""
    return (label, list(sets), scene)


# Knobs: name -> (problem, what it trades, [settings] most accurate first, label of the most
# accurate setting (the reference), labels of the --quick subset). Every setting's overrides apply
# to its scene (the problem's base scene unless it names one). When the reference run did not
# finish, the most accurate finished setting is the reference (marked "ref*" in the table).
def knobs(quick):
    f = {}
    f["scale"] = ("footing", "particle upscaling factor (fewer, larger balls)",
                  [setting("1", "dem.specimen.scale=1"), setting("1.3", "dem.specimen.scale=1.3"),
                   setting("1.5", "dem.specimen.scale=1.5"), setting("2", "dem.specimen.scale=2")], "1", ["1.5", "2"])
    f["interval"] = ("footing", "DEM steps per coupling exchange",
                     [setting("1"), setting("2", "coupling.interval=2"), setting("5", "coupling.interval=5"),
                      setting("10", "coupling.interval=10")], "1", ["1", "5"])
    f["scheme"] = ("footing", "serial (no lag) or parallel (one-step lag, both cores busy) coupling",
                   [setting("serial"), setting("parallel", 'coupling.scheme="parallel"')], "serial",
                   ["serial", "parallel"])
    # Coupled DEM-FDM against a DEM-only box of the same 4 x 4 x 4 mm outer size, at upscaling 2
    # (the smallest practical DEM-only model): the DEM box (BOX_SCENE: replication 2 x 2 x 4, box
    # of walls) is the reference.
    f["dem_only"] = ("footing", "a DEM block in an FDM continuum instead of DEM everywhere (same 4 mm box, scale 2)",
                     [setting("dem_box", "dem.specimen.scale=2", scene=BOX_SCENE),
                      setting("coupled", "dem.specimen.scale=2", "continuum.mesh.size=[4e-3, 4e-3, 4e-3]",
                              "dem.specimen.replicate=[1, 1, 2]", "continuum.mesh.inner_size=[2e-3, 2e-3, 2e-3]")],
                     "dem_box", [])
    f["dt_safety"] = ("footing", "time step as a fraction of the critical step (DEM dt_safety; FDM "
                      "timestep_safety scaled by the same factor)",
                      [setting("0.4", "dem.dt_safety=0.4", "continuum.timestep_safety=0.25"),
                       setting("0.64", "dem.dt_safety=0.64", "continuum.timestep_safety=0.4"),
                       setting("0.8"),
                       setting("0.95", "dem.dt_safety=0.95", "continuum.timestep_safety=0.59375")], "0.4",
                      ["0.8", "0.95"])
    f["zone_size"] = ("footing", "FDM zone size (size_near and size_far times the factor)",
                      [setting("0.5", "continuum.mesh.size_near=0.25e-3", "continuum.mesh.size_far=0.75e-3"),
                       setting("1"),
                       setting("2", "continuum.mesh.size_near=1e-3", "continuum.mesh.size_far=3e-3")], "0.5",
                      ["1", "2"])
    f["continuum"] = ("footing", "explicit FDM or the implicit continuum solver (fem_node)",
                      [setting("fdm"), setting("fem", 'continuum.executable="fem_node"')], "fdm", [])
    f["damping"] = ("footing", "DEM local damping alpha of the penetration stage (the gravity stage keeps 0.7)",
                    [setting("0.1", "stage.penetrate.damping=0.1"), setting("0.3", "stage.penetrate.damping=0.3"),
                     setting("0.7")], "0.1", [])
    f["seed"] = ("footing", "generator seed: not a trade, the run-to-run scatter an error must exceed to mean anything",
                 [setting("1"), setting("2", "run.seed=2"), setting("3", "run.seed=3")], "1", [])
    f["ucs_scale"] = ("ucs", "particle upscaling factor of the UCS test",
                      [setting("1", "dem.specimen.scale=1"), setting("1.3", "dem.specimen.scale=1.3"),
                       setting("1.5", "dem.specimen.scale=1.5"), setting("2", "dem.specimen.scale=2")], "1",
                      ["1.5", "2"])
    if quick:  # the subsets, each against its own most accurate member
        out = {}
        for k, (prob, what, sets, ref, sub) in f.items():
            if sub:
                chosen = [s for s in sets if s[0] in sub]
                out[k] = (prob, what, chosen, chosen[0][0], sub)
        return out
    return f


def base_sets(problem, quick):
    """The overrides every run of a problem starts with: --quick's development settings."""
    if not quick:
        return []
    if problem == "footing":  # larger balls, shallower penetration
        return ["dem.specimen.scale=2", "stage.penetrate.depth_ratio=0.05"]
    return ["stage.ucs.max_strain=0.002"]


class PlanError(Exception):
    """A setting the coordinator refuses, or a study folder that ran other values: exit 2."""


def existing_runs(study, coordinator=None):
    """fingerprint -> run name of the run folders already in a study folder (their scene.toml read
    through the coordinator: an effective scene, or the edited scene copy of a study written
    before the studies used overrides), so that extending or resuming a study reuses them."""
    out = {}
    if os.path.isdir(study):
        for name in sorted(os.listdir(study)):
            v = overrides.run_values(os.path.join(study, name), coordinator)
            if v is not None:
                out.setdefault(overrides.digest(v), name)
    return out


def plan(root, quick, only, existing=None, seeds=1, coordinator=None):
    """Runs to make ({fingerprint: {name, scene, sets}}) and table entries. With seeds > 1 every
    footing setting runs with the generator seeds 1..seeds and is measured on the seed-averaged
    curve (the footing's single-run scatter is large at this size); the seed knob is then dropped
    (its role is the table's scatter column). Every run is checked by the coordinator here
    (coordinator SCENE --check --set ...): a setting it refuses raises PlanError with its error
    line."""
    ks = knobs(quick)
    if seeds > 1:
        ks.pop("seed", None)
    if only:
        bad = [k for k in only if k not in ks]
        if bad:
            raise PlanError("unknown knob(s) %s; knobs%s: %s" % (" ".join(bad), " (--quick)" if quick else "",
                                                                 " ".join(ks)))
        ks = {k: ks[k] for k in only}
    runs, entries = {}, []
    taken = {}  # run name -> fingerprint, of the study folder's runs
    for fp, name in (existing or {}).items():
        runs[fp] = {"name": name, "scene": None}
        taken[name] = fp
    for k, (prob, what, sets, ref, _) in ks.items():
        for label, extra, scene in sets:
            path = os.path.join(root, scene or BASE_SCENES[prob])
            names = []
            for sd in (range(1, seeds + 1) if prob == "footing" and seeds > 1 else [None]):
                s = base_sets(prob, quick) + extra + ([] if sd is None else ["run.seed=%d" % sd])
                s = overrides.quiet_traffic(path, overrides.merge(s))
                try:
                    fp = overrides.fingerprint(path, s, coordinator)
                except ValueError as ex:
                    raise PlanError("knob %s, setting %s: %s" % (k, label, ex))
                name = "%s_%s_%s%s" % (prob, k, label, "" if sd is None else "_s%d" % sd)
                if fp not in runs and taken.get(name, fp) != fp:
                    raise PlanError("the study folder's run %s ran other values than knob %s, setting %s now "
                                    "gives (a scene changed?); use a new study folder, or remove that run folder"
                                    % (name, k, label))
                r = runs.setdefault(fp, {"name": name})
                r.update(scene=path, sets=s)
                names.append(r["name"])
            entries.append({"problem": prob, "knob": k, "what": what, "setting": label, "reference": label == ref,
                            "run": names[0], "runs": names})
    planned = {h: r for h, r in runs.items() if r["scene"] is not None}
    for r in planned.values():  # as launch/run checks it: the scene, then every node executable
        ok, msg = overrides.check(r["scene"], r["sets"], coordinator)
        if not ok:
            raise PlanError("run %s: %s" % (r["name"], msg))
    return planned, entries


def command(root, r, launcher=None):
    """The launch/run command of a planned run (without --no-build, --run-dir and --from)."""
    return [launcher or os.path.join(root, "launch/run"), r["scene"]] + overrides.set_args(r["sets"])


def run_order(runs):
    """Footing runs first, then the UCS runs from the coarsest to the finest (scale 1, the longest, last)."""
    order = list(runs.values())
    return [r for r in order if not r["name"].startswith("ucs_")] + \
        [r for r in reversed(order) if r["name"].startswith("ucs_")]


def run_all(root, study, runs, branch=True, coordinator=None, launcher=None):
    coordinator = list(coordinator) if coordinator else branching.coordinator_command()
    order = run_order(runs)
    for i, r in enumerate(order):
        d = os.path.join(study, r["name"])
        if os.path.exists(os.path.join(d, "summary.json")):
            continue
        if os.path.exists(d):  # launch/run never overwrites a run folder
            print("accuracy study: %s failed in an earlier pass (remove its folder to run it again)" % r["name"],
                  file=sys.stderr)
            continue
        # A run that shares its first stages with a finished one starts from its saved state
        # (launch/py/branching.py; the coordinator decides, with the run's overrides; the same
        # bits as from scratch).
        others = [os.path.join(study, o["name"]) for o in order if o is not r]
        source = branching.branch_source(coordinator + overrides.set_args(r["sets"]), r["scene"], others) \
            if branch else None
        t0 = time.time()
        cmd = command(root, r, launcher) + ["--no-build", "--run-dir", d] + (["--from", source] if source else [])
        with open(os.path.join(study, r["name"] + ".log"), "w") as log:
            rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT)
        print("accuracy study: [%d/%d] %s %s in %.0f s%s" % (i + 1, len(order), r["name"],
                                                             "done" if rc == 0 else "FAILED (rc %d)" % rc,
                                                             time.time() - t0,
                                                             ", branched from " + os.path.relpath(source, study)
                                                             if source else ""), file=sys.stderr, flush=True)


def print_plan(root, study, runs, entries):
    """The plan for people: every distinct run with its launch/run command (and, with a study
    folder, whether it has run), then which run serves which knob setting."""
    order = run_order(runs)
    print("# %d distinct runs (each checked by the coordinator)" % len(order))
    for r in order:
        state = ""
        if study:
            d = os.path.join(study, r["name"])
            state = ("finished" if branching.finished(d) else "failed or unfinished" if os.path.exists(d)
                     else "to run") + ": "
        cmd = [os.path.relpath(c, root) for c in command(root, r)[:2]] + command(root, r)[2:]
        print("%s%s: %s" % (state, r["name"], shlex.join(cmd)))
    print("# knob settings -> runs")
    for e in entries:
        print("%-9s %-10s %-8s%s %s" % (e["problem"], e["knob"], e["setting"], " (ref)" if e["reference"] else "      ",
                                       " ".join(e["runs"])))


def run_wall(d):
    p = os.path.join(d, "summary.json")
    if os.path.exists(p):
        j = json.load(open(p))
        comp = j["totals"]["nodes"]
        return j["totals"]["wall_s"], sum(n["compute_s"] for n in comp.values()), j["totals"]["steps"]
    m = re.search(r"^total: (\d+) coupling steps in ([0-9.]+) s", open(os.path.join(d, "summary.txt")).read(), re.M)
    return float(m.group(2)), float("nan"), int(m.group(1))


def mean_curve(curves, n=400):
    """Seed average: the loads of several curves interpolated onto a common displacement grid
    (0 to the shortest stroke) and averaged; also the standard error of that mean, as the RMS over
    the grid of the seeds' standard deviation / sqrt(seeds)."""
    xmax = min(float(np.max(x)) for x, _ in curves)
    grid = np.linspace(0.0, xmax, n)
    ys = np.array([np.interp(grid, x, y) for x, y in curves])
    se = float(np.sqrt(np.mean(ys.std(axis=0, ddof=1) ** 2)) / np.sqrt(len(curves))) if len(curves) > 1 else float("nan")
    return grid, ys.mean(axis=0), se


def measures(problem, d, d_f):
    """(peak, initial stiffness, x, y, se) of a finished run: footing load-displacement or UCS
    stress-strain. d: a run folder, or a list of run folders (seeds) measured on their mean curve;
    se: the mean curve's standard error over its peak (NaN for one run)."""
    if problem == "footing":
        # Several seeds: peak and initial stiffness are the means of the runs' own figures (a peak
        # of the mean curve would be smoothed away where the runs' peaks fall at different
        # displacements); the curve is the seed-mean curve.
        ds = d if isinstance(d, list) else [d]
        curves = [paper_figures.curve(r) for r in ds]
        peak = float(np.mean([np.max(y) for _, y in curves]))
        ks = [paper_figures.initial_stiffness(x, y, d_f)[0] for x, y in curves]
        ks = [k for k in ks if np.isfinite(k)]
        k = float(np.mean(ks)) if ks else float("nan")
        if len(ds) == 1:
            return peak, k, curves[0][0], curves[0][1], float("nan")
        x, y, se = mean_curve(curves)
        return peak, k, x, y, se / abs(peak)
    res = paper_figures.read_csv(os.path.join(d, "ucs_result.csv"))
    c = paper_figures.read_csv(os.path.join(d, "ucs_curve.csv"))
    return float(res["ucs_Pa"][0]), float(res["e50_Pa"][0]), c["strain_unit"], c["stress_Pa"], float("nan")


def rel(a, b):
    return abs(a - b) / abs(b) if np.isfinite(a) and np.isfinite(b) and b != 0 else float("nan")


def table(study):
    meta = json.load(open(os.path.join(study, "plan.json")))
    d_f = meta["d_f"]
    done = {}

    def finished(name):
        d = os.path.join(study, name)
        return os.path.exists(os.path.join(d, "summary.json")) or (
            os.path.exists(os.path.join(d, "summary.txt")) and not open(os.path.join(d, "summary.txt")).read().startswith("FAILED"))
    for e in meta["entries"]:
        names = e.get("runs", [e["run"]])
        if all(finished(n) for n in names) and e["run"] not in done:
            ds = [os.path.join(study, n) for n in names]
            try:
                walls = [run_wall(d) for d in ds]  # per-setting cost: the mean over its seeds
                cost = tuple(float(np.mean([w[i] for w in walls])) for i in range(3))
                done[e["run"]] = (cost,) + measures(e["problem"], ds if len(ds) > 1 else ds[0], d_f)
            except (OSError, ValueError, KeyError) as ex:
                print("accuracy study: %s: no result (%s)" % (e["run"], ex), file=sys.stderr)
    refs = {}
    for e in meta["entries"]:  # entries are in order of accuracy within a knob
        if e["knob"] not in refs and e["run"] in done:
            refs[e["knob"]] = e
    rows = []
    for e in meta["entries"]:
        ref = refs.get(e["knob"])
        is_ref = ref is e if ref is not None else e["reference"]
        row = dict(problem=e["problem"], knob=e["knob"], setting=e["setting"],
                   reference=(2 if is_ref and not e["reference"] else int(is_ref)),
                   run=e["run"], wall_s=float("nan"), compute_s=float("nan"), steps=float("nan"), peak=float("nan"),
                   peak_err=float("nan"),
                   stiffness=float("nan"), stiffness_err=float("nan"), curve_err=float("nan"),
                   seeds=len(e.get("runs", [e["run"]])), curve_se=float("nan"))
        if e["run"] in done:
            (wall, comp, steps), peak, k, x, y, se = done[e["run"]]
            row.update(wall_s=wall, compute_s=comp, steps=steps, peak=peak, stiffness=k, curve_se=se)
            if ref is not None:
                _, rpeak, rk, rx, ry, _ = done[ref["run"]]
                row.update(peak_err=rel(peak, rpeak), stiffness_err=rel(k, rk),
                           curve_err=compare_curves.curve_difference((rx, ry), (x, y), abs(rpeak))[0])
        rows.append(row)
    names = list(rows[0])
    with open(os.path.join(study, "accuracy_table.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=names)
        w.writeheader()
        w.writerows(rows)
    units = {"footing": ("peak load [N]", "k0 [N/m]"), "ucs": ("UCS [Pa]", "E50 [Pa]")}
    lines = ["| problem | knob | setting | wall [s] | compute [s] | coupling steps | peak | peak err | initial stiffness "
             "| stiffness err | curve err | seeds | curve s.e. |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def pct(v):
        return "-" if not np.isfinite(v) else "%.2f %%" % (100 * v)

    def num(v, spec):
        return "-" if not np.isfinite(v) else format(v, spec)
    for r in rows:
        lines.append("| %s | %s | %s%s | %s | %s | %s | %s | %s | %s | %s | %s | %d | %s |" % (
            r["problem"], r["knob"], r["setting"], {0: "", 1: " (ref)", 2: " (ref*)"}[r["reference"]], num(r["wall_s"], ".0f"),
            num(r["compute_s"], ".0f"), num(r["steps"], ".0f"), num(r["peak"], ".4g"), pct(r["peak_err"]), num(r["stiffness"], ".4g"),
            pct(r["stiffness_err"]), pct(r["curve_err"]), r["seeds"], pct(r["curve_se"])))
    text = ("# Accuracy-cost study\n\nErrors against the reference (most accurate) setting of each knob. "
            "Footing: peak = %s, initial stiffness = %s; UCS: peak = %s, initial stiffness = %s. Curve err: RMS "
            "difference over the common range / reference peak. wall: the coordinator's run wall time; compute: "
            "CPU-busy seconds of all nodes; coupling steps: the run's total (DEM steps = steps x interval); with several "
            "seeds, peak, initial stiffness (k50) and the costs are means over the seeds' runs, the curve error compares "
            "the seed-mean curves (mean load on a common displacement grid up to the shortest stroke); curve s.e.: the "
            "standard error of the seed-mean curve (RMS over the stroke) / its peak: curve errors below about twice "
            "the two settings' s.e. are not resolved. ref*: the knob's most accurate setting did not finish; the most accurate "
            "finished one is the reference.\n\n" % (units["footing"] + units["ucs"])) + "\n".join(lines) + "\n"
    open(os.path.join(study, "accuracy_table.md"), "w").write(text)
    print(text)
    pareto_figure(study, rows)


def pareto_front(points):
    """Indices of the points (t, e) that no other point beats in both time and error."""
    idx = []
    for i, (t, e) in enumerate(points):
        if not any((t2 <= t and e2 <= e) and (t2 < t or e2 < e) for j, (t2, e2) in enumerate(points) if j != i):
            idx.append(i)
    return sorted(idx, key=lambda i: points[i][0])


def pareto_figure(study, rows):
    problems = [p for p in ("footing", "ucs") if any(r["problem"] == p for r in rows)]
    fig, axes = plt.subplots(1, len(problems), figsize=(6.5 * len(problems), 5), squeeze=False)
    floor = 1e-4  # errors of reference runs (0) are drawn at this floor
    for ax, prob in zip(axes[0], problems):
        rs = [r for r in rows if r["problem"] == prob and np.isfinite(r["wall_s"]) and np.isfinite(r["curve_err"])]
        for i, k in enumerate(dict.fromkeys(r["knob"] for r in rs)):
            kr = [r for r in rs if r["knob"] == k]
            ax.plot([r["wall_s"] for r in kr], [max(r["curve_err"], floor) for r in kr], "o-", color="C%d" % i, label=k,
                    alpha=0.8)
            for r in kr:
                ax.annotate(r["setting"], (r["wall_s"], max(r["curve_err"], floor)), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
        # The front over the non-reference runs: a reference's zero error is against itself.
        others = [r for r in rs if not r["reference"]]
        pts = [(r["wall_s"], max(r["curve_err"], floor)) for r in others]
        front = pareto_front(pts)
        scatter = [r["curve_err"] for r in others if r["knob"] == "seed"]
        if scatter:
            ax.axhline(np.mean(scatter), color="0.5", ls=":", label="seed scatter (mean curve error)")
        if front:
            ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", lw=1.5, label="Pareto front")
            ax.scatter([pts[i][0] for i in front], [pts[i][1] for i in front], s=120, facecolors="none",
                       edgecolors="k")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("run wall time [s]")
        ax.set_ylabel("curve error (RMS / reference peak; references drawn at %g)" % floor)
        ax.set_title("%s: error against the knob's reference vs time" % prob)
        ax.grid(True, which="both", alpha=0.3)
        if rs:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(study, "accuracy_pareto.png"), dpi=120)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("command", choices=["run", "plan", "table", "list"])
    ap.add_argument("study", nargs="?")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", nargs="+", default=[])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--no-branch", action="store_true", help="run every scene from scratch (no launch/run --from)")
    ap.add_argument("--launcher", help=argparse.SUPPRESS)  # tests: a stand-in for launch/run
    a = ap.parse_args()
    root = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    if a.command == "list":
        for k, (prob, what, sets, ref, sub) in knobs(False).items():
            print("%-10s %-8s %s: %s (reference %s; --quick: %s)" % (k, prob, what, " / ".join(s[0] for s in sets), ref,
                                                                     " / ".join(sub) or "skipped"))
        return 0
    if a.command == "plan":
        try:
            runs, entries = plan(root, a.quick, a.only, existing_runs(a.study) if a.study else None, a.seeds)
        except PlanError as ex:
            print("accuracy study: %s" % ex, file=sys.stderr)
            return 2
        print_plan(root, a.study, runs, entries)
        return 0
    if not a.study:
        ap.error("%s needs STUDY_DIR" % a.command)
    if a.command == "run":
        plan_path = os.path.join(a.study, "plan.json")
        old = json.load(open(plan_path)) if os.path.exists(plan_path) else None
        if old is not None:  # extend an existing study (e.g. --only KNOB into the same folder)
            if old["quick"] != a.quick:
                print("accuracy study: %s is a %s study" % (a.study, "quick" if old["quick"] else "full"), file=sys.stderr)
                return 2
            if old.get("seeds", 1) != a.seeds:
                print("accuracy study: %s was planned with --seeds %d" % (a.study, old.get("seeds", 1)), file=sys.stderr)
                return 2
        try:
            runs, entries = plan(root, a.quick, a.only, existing_runs(a.study), a.seeds)
        except PlanError as ex:
            print("accuracy study: %s" % ex, file=sys.stderr)
            return 2
        os.makedirs(a.study, exist_ok=True)
        d_f = float(overrides.scene_values(os.path.join(root, FOOTING_SCENE))["dem"]["footing"]["diameter"])
        described = dict(old.get("runs", {})) if old else {}
        described.update({r["name"]: {"scene": os.path.relpath(r["scene"], root), "set": r["sets"]}
                          for r in runs.values()})
        if old is not None:
            have = {(e["knob"], e["setting"]) for e in entries}
            entries = [e for e in old["entries"] if (e["knob"], e["setting"]) not in have] + entries
        json.dump({"quick": a.quick, "seeds": a.seeds, "d_f": d_f, "entries": entries, "runs": described},
                  open(plan_path, "w"), indent=1)
        print("accuracy study: %d settings, %d distinct runs in %s" % (len(entries), len(runs), a.study), file=sys.stderr)
        run_all(root, a.study, runs, branch=not a.no_branch, launcher=a.launcher)
    table(a.study)
    return 0


if __name__ == "__main__":
    sys.exit(main())

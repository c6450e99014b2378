#!/usr/bin/python3
"""Accuracy-cost study (launch/study accuracy; docs/accuracy-study.md).

Usage:
  /usr/bin/python3 launch/py/accuracy_study.py run STUDY_DIR [--quick] [--only KNOB ...]
  /usr/bin/python3 launch/py/accuracy_study.py table STUDY_DIR
  /usr/bin/python3 launch/py/accuracy_study.py list

run: derives every variant of each knob from scenes/accuracy_footing.toml (footing) or
scenes/ucs_sbm_s1.5.toml (UCS) by setting `table.key = value` in the scene text, runs each
distinct scene once through launch/run (sequentially, one thread per node), then writes the table
and the figure. table: rebuilds accuracy_table.{csv,md} and accuracy_pareto.png from the run
folders of STUDY_DIR (plan.json). Needs DEMFDM_ROOT (and DEMFDM_BUILD for launch/run).

For each run: wall time of the run (summary.json totals, the coordinator's clock), and the error
against the most accurate setting of its knob: peak load (UCS: the UCS), initial stiffness
(paper_figures.initial_stiffness; UCS: E50), and the whole curve's normalised difference
(compare_curves.curve_difference: RMS of the load difference over the common displacement range
/ reference peak; UCS: stress over strain).
"""
import argparse
import csv
import hashlib
import json
import os
import re
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

FOOTING_SCENE = "scenes/accuracy_footing.toml"
UCS_SCENE = "scenes/ucs_sbm_s1.5.toml"


def set_key(text, dotted, value):
    """Sets `key = value` in table `table` ("table.key"; the first [[table]] of an array of tables)
    of a TOML text. Fails when the table or the key is not in the text (no silent additions)."""
    table, _, key = dotted.rpartition(".")
    lines = text.split("\n")
    start = None
    for i, line in enumerate(lines):
        s = line.strip()
        if s in ("[%s]" % table, "[[%s]]" % table):
            start = i + 1
            break
    if start is None:
        raise KeyError("scene has no table [%s] (setting %s)" % (table, dotted))
    for i in range(start, len(lines)):
        s = lines[i].strip()
        if s.startswith("["):
            break
        m = re.match(r"^(\s*)%s\s*=" % re.escape(key), lines[i])
        if m:
            lines[i] = "%s%s = %s" % (m.group(1), key, value)
            return "\n".join(lines)
    raise KeyError("table [%s] of the scene has no key '%s'" % (table, key))


def quiet_traffic(text):
    """Study and ensemble runs record no traffic log unless the scene says traffic_log itself: a
    coupled run's log holds every interface message (about 1 GB for the default scene), which a
    study of load curves does not need. [output] traffic_log = false is added."""
    if re.search(r"(?m)^\s*traffic_log\s*=", text):
        return text
    if re.search(r"(?m)^\s*\[output\]\s*$", text):
        return re.sub(r"(?m)^(\s*\[output\]\s*)$", r"\1\ntraffic_log = false", text, count=1)
    return text.rstrip("\n") + "\n\n[output]\ntraffic_log = false\n"


def set_stage_key(text, stage, key, value, add=False):
    """Sets `key = value` in the [[stage]] named `stage`; fails when the stage is absent, and when
    the key is absent unless add (then the line is appended to the stage)."""
    parts = re.split(r"(?m)^(?=\[\[stage\]\])", text)
    for i, p in enumerate(parts):
        if p.startswith("[[stage]]") and re.search(r'(?m)^name\s*=\s*"%s"\s*$' % re.escape(stage), p):
            new, n = re.subn(r"(?m)^%s\s*=.*$" % re.escape(key), "%s = %s" % (key, value), p)
            if n == 0 and add:
                body = p.rstrip("\n")
                new, n = body + "\n%s = %s\n" % (key, value) + p[len(body):].lstrip("\n"), 1
                new = new if new.endswith("\n") else new + "\n"
            if n != 1:
                raise KeyError("stage '%s' has %d '%s' keys (expected 1)" % (stage, n, key))
            parts[i] = new
            return "".join(parts)
    raise KeyError("scene has no stage named '%s'" % stage)


def dem_only_box(text):
    """The footing scene without its continuum: drops [continuum*] and [coupling], turns the
    coupled gravity stage into a DEM equilibrium stage and puts the block in a box of walls
    (dem.specimen.box = "walls"). The caller sets the replication so that the DEM block fills
    the outer size of the coupled model."""
    out, skip = [], False
    for line in text.split("\n"):
        s = line.strip()
        if s.startswith("["):
            name = s.strip("[]")
            skip = name.startswith("continuum") or name == "coupling"
        if skip:
            continue
        if re.match(r"^coupled\s*=", s):
            continue
        out.append(line)
    text = "\n".join(out)
    text, n = re.subn(r'(?m)^action\s*=\s*"couple"\s*$', 'action = "equilibrium"', text)
    if n != 1:
        raise KeyError("footing scene: expected one stage with action \"couple\", found %d" % n)
    if "\n[dem.specimen]\n" not in text:
        raise KeyError("footing scene has no [dem.specimen] table")
    return text.replace("\n[dem.specimen]\n", '\n[dem.specimen]\nbox = "walls"\n', 1)


def apply(text, edits):
    for k, v in edits.items():
        if k == "transform" and v == "dem_only_box":
            text = dem_only_box(text)
        elif k.startswith("stage:") or k.startswith("stage+:"):
            stage, _, key = k.partition(":")[2].partition(".")
            text = set_stage_key(text, stage, key, v, add=k.startswith("stage+:"))
        else:
            text = set_key(text, k, v)
    return text


# Knobs: name -> (problem, what it trades, [(label, edits)] most accurate first, label of the most
# accurate setting (the reference), labels of the --quick subset). Every label's edits apply to the
# problem's base scene. When the reference run did not finish, the most accurate finished setting
# is the reference (marked "ref*" in the table).
def knobs(quick):
    f = {}
    f["scale"] = ("footing", "particle upscaling factor (fewer, larger balls)",
                  [("1", {"dem.specimen.scale": 1}), ("1.3", {"dem.specimen.scale": 1.3}),
                   ("1.5", {"dem.specimen.scale": 1.5}), ("2", {"dem.specimen.scale": 2})], "1", ["1.5", "2"])
    f["interval"] = ("footing", "DEM steps per coupling exchange",
                     [("1", {}), ("2", {"coupling.interval": 2}), ("5", {"coupling.interval": 5}),
                      ("10", {"coupling.interval": 10})], "1", ["1", "5"])
    f["scheme"] = ("footing", "serial (no lag) or parallel (one-step lag, both cores busy) coupling",
                   [("serial", {}), ("parallel", {"coupling.scheme": '"parallel"'})], "serial", ["serial", "parallel"])
    # Coupled DEM-FDM against a DEM-only box of the same 4 x 4 x 4 mm outer size, at upscaling 2
    # (the smallest practical DEM-only model): the DEM box is the reference.
    small = {"dem.specimen.scale": 2, "continuum.mesh.size": "[4e-3, 4e-3, 4e-3]"}
    f["dem_only"] = ("footing", "a DEM block in an FDM continuum instead of DEM everywhere (same 4 mm box, scale 2)",
                     [("dem_box", dict(small, **{"dem.specimen.replicate": "[2, 2, 4]", "transform": "dem_only_box"})),
                      ("coupled", dict(small, **{"dem.specimen.replicate": "[1, 1, 2]",
                                                 "continuum.mesh.inner_size": "[2e-3, 2e-3, 2e-3]"}))],
                     "dem_box", [])
    f["dt_safety"] = ("footing", "time step as a fraction of the critical step (DEM dt_safety; FDM "
                      "timestep_safety scaled by the same factor)",
                      [("0.4", {"dem.dt_safety": 0.4, "continuum.timestep_safety": 0.25}),
                       ("0.64", {"dem.dt_safety": 0.64, "continuum.timestep_safety": 0.4}),
                       ("0.8", {}),
                       ("0.95", {"dem.dt_safety": 0.95, "continuum.timestep_safety": 0.59375})], "0.4", ["0.8", "0.95"])
    f["zone_size"] = ("footing", "FDM zone size (size_near and size_far times the factor)",
                      [("0.5", {"continuum.mesh.size_near": 0.25e-3, "continuum.mesh.size_far": 0.75e-3}),
                       ("1", {}),
                       ("2", {"continuum.mesh.size_near": 1e-3, "continuum.mesh.size_far": 3e-3})], "0.5", ["1", "2"])
    f["continuum"] = ("footing", "explicit FDM or the implicit continuum solver (fem_node)",
                      [("fdm", {}), ("fem", {"continuum.executable": '"fem_node"'})], "fdm", [])
    f["damping"] = ("footing", "DEM local damping alpha of the penetration stage (the gravity stage keeps 0.7)",
                    [("0.1", {"stage+:penetrate.damping": 0.1}), ("0.3", {"stage+:penetrate.damping": 0.3}),
                     ("0.7", {})], "0.1", [])
    f["seed"] = ("footing", "generator seed: not a trade, the run-to-run scatter an error must exceed to mean anything",
                 [("1", {}), ("2", {"run.seed": 2}), ("3", {"run.seed": 3})], "1", [])
    f["ucs_scale"] = ("ucs", "particle upscaling factor of the UCS test",
                      [("1", {"dem.specimen.scale": 1}), ("1.3", {"dem.specimen.scale": 1.3}),
                       ("1.5", {"dem.specimen.scale": 1.5}), ("2", {"dem.specimen.scale": 2})], "1", ["1.5", "2"])
    if quick:  # the subsets, each against its own most accurate member
        out = {}
        for k, (prob, what, sets, ref, sub) in f.items():
            if sub:
                chosen = [s for s in sets if s[0] in sub]
                out[k] = (prob, what, chosen, chosen[0][0], sub)
        return out
    return f


def base_text(root, problem, quick):
    if problem == "footing":
        text = quiet_traffic(open(os.path.join(root, FOOTING_SCENE)).read())
        if quick:  # development: larger balls, shallower penetration
            text = apply(text, {"dem.specimen.scale": 2, "stage:penetrate.depth_ratio": 0.05})
        return text
    text = quiet_traffic(open(os.path.join(root, UCS_SCENE)).read())
    if quick:
        text = apply(text, {"stage:ucs.max_strain": 0.002})
    return text


def text_hash(text):
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def existing_runs(study):
    """hash -> run name of the scenes already written to a study folder (reused when extending it)."""
    out = {}
    if os.path.isdir(study):
        for f in sorted(os.listdir(study)):
            if f.endswith(".toml"):
                out.setdefault(text_hash(open(os.path.join(study, f)).read()), {"name": f[:-5]})
    return out


def plan(root, quick, only, existing=None, seeds=1):
    """Runs to make and table entries. With seeds > 1 every footing setting runs with the generator
    seeds 1..seeds and is measured on the seed-averaged curve (the footing's single-run scatter is
    large at this size); the seed knob is then dropped (its role is the table's scatter column)."""
    ks = knobs(quick)
    if seeds > 1:
        ks.pop("seed", None)
    if only:
        bad = [k for k in only if k not in ks]
        if bad:
            print("accuracy study: unknown knob(s) %s; knobs%s: %s" %
                  (" ".join(bad), " (--quick)" if quick else "", " ".join(ks)), file=sys.stderr)
            raise SystemExit(2)
        ks = {k: ks[k] for k in only}
    runs, entries = {}, []
    for h, r in (existing or {}).items():
        runs[h] = dict(r, text=None)
    for k, (prob, what, sets, ref, _) in ks.items():
        base = base_text(root, prob, quick)
        for label, edits in sets:
            names = []
            for sd in (range(1, seeds + 1) if prob == "footing" and seeds > 1 else [None]):
                e2 = dict(edits)
                if sd is not None:
                    e2["run.seed"] = sd
                text = apply(base, e2)
                h = text_hash(text)
                r = runs.setdefault(h, {"name": "%s_%s_%s%s" % (prob, k, label, "" if sd is None else "_s%d" % sd),
                                        "text": text})
                r["text"] = text
                names.append(r["name"])
            entries.append({"problem": prob, "knob": k, "what": what, "setting": label, "reference": label == ref,
                            "run": names[0], "runs": names})
    return {h: r for h, r in runs.items() if r["text"] is not None}, entries


def run_all(root, study, runs, branch=True):
    # Footing runs first, then the UCS runs from the coarsest to the finest (scale 1, the longest, last).
    order = list(runs.values())
    order = [r for r in order if not r["name"].startswith("ucs_")] + \
        [r for r in reversed(order) if r["name"].startswith("ucs_")]
    for i, r in enumerate(order):
        d = os.path.join(study, r["name"])
        if os.path.exists(os.path.join(d, "summary.json")):
            continue
        if os.path.exists(d):  # launch/run never overwrites a run folder
            print("accuracy study: %s failed in an earlier pass (remove its folder to run it again)" % r["name"],
                  file=sys.stderr)
            continue
        scene = os.path.join(study, r["name"] + ".toml")
        open(scene, "w").write(r["text"])
        # A run that shares its first stages with a finished one starts from its saved state
        # (launch/py/branching.py; the same bits as from scratch).
        others = [os.path.join(study, o["name"]) for o in order if o is not r]
        source = branching.branch_source(branching.coordinator_command(), scene, others) if branch else None
        t0 = time.time()
        with open(os.path.join(study, r["name"] + ".log"), "w") as log:
            rc = subprocess.call([os.path.join(root, "launch/run"), scene, "--no-build", "--run-dir", d] +
                                 (["--from", source] if source else []), stdout=log, stderr=subprocess.STDOUT)
        print("accuracy study: [%d/%d] %s %s in %.0f s%s" % (i + 1, len(order), r["name"],
                                                             "done" if rc == 0 else "FAILED (rc %d)" % rc,
                                                             time.time() - t0,
                                                             ", branched from " + os.path.relpath(source, study)
                                                             if source else ""), file=sys.stderr, flush=True)


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
    ap.add_argument("command", choices=["run", "table", "list"])
    ap.add_argument("study", nargs="?")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", nargs="+", default=[])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--no-branch", action="store_true", help="run every scene from scratch (no launch/run --from)")
    a = ap.parse_args()
    root = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    if a.command == "list":
        for k, (prob, what, sets, ref, sub) in knobs(False).items():
            print("%-10s %-8s %s: %s (reference %s; --quick: %s)" % (k, prob, what, " / ".join(s[0] for s in sets), ref,
                                                                     " / ".join(sub) or "skipped"))
        return
    if not a.study:
        ap.error("%s needs STUDY_DIR" % a.command)
    if a.command == "run":
        runs, entries = plan(root, a.quick, a.only, existing_runs(a.study), a.seeds)
        os.makedirs(a.study, exist_ok=True)
        d_f = float(re.search(r"(?m)^diameter = (\S+)", open(os.path.join(root, FOOTING_SCENE)).read()).group(1))
        plan_path = os.path.join(a.study, "plan.json")
        if os.path.exists(plan_path):  # extend an existing study (e.g. --only KNOB into the same folder)
            old = json.load(open(plan_path))
            if old["quick"] != a.quick:
                raise SystemExit("accuracy study: %s is a %s study" % (a.study, "quick" if old["quick"] else "full"))
            if old.get("seeds", 1) != a.seeds:
                raise SystemExit("accuracy study: %s was planned with --seeds %d" % (a.study, old.get("seeds", 1)))
            have = {(e["knob"], e["setting"]) for e in entries}
            entries = [e for e in old["entries"] if (e["knob"], e["setting"]) not in have] + entries
        json.dump({"quick": a.quick, "seeds": a.seeds, "d_f": d_f, "entries": entries}, open(plan_path, "w"), indent=1)
        print("accuracy study: %d settings, %d distinct runs in %s" % (len(entries), len(runs), a.study), file=sys.stderr)
        run_all(root, a.study, runs, branch=not a.no_branch)
    table(a.study)


if __name__ == "__main__":
    main()

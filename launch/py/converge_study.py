#!/usr/bin/python3
"""Convergence study of the footing prediction (launch/study converge; docs/convergence.md).

Usage:
  /usr/bin/python3 launch/py/converge_study.py run STUDY_DIR [--parts rate dt] [--seeds N]
                                                [--jobs J] [--rate I] [--damping A] [--quick]
                                                [--only VARIANT ...] [--no-branch]
  /usr/bin/python3 launch/py/converge_study.py table STUDY_DIR
  /usr/bin/python3 launch/py/converge_study.py list [--parts ...] [--rate I] [--damping A] [--quick]
                                                 [--seeds N] [--check]

Every variant is an ensemble over seeds 1..N of scenes/accuracy_footing.toml with some keys
overridden (launch/run --set; the DEM-everywhere arm of the box part: scenes/accuracy_footing_box.toml,
the same problem without its continuum, whose header lists the differences); seed k adds
run.seed=k, and no run records a traffic log unless the scene says so (output.traffic_log=false).
Its runs go to STUDY_DIR/<variant>/seed-<k>/ (launch/run folders; each records its effective
scene as scene.toml, launch/run's output goes to <variant>/seed-<k>.out). Specimen preparation
does not depend on the knobs varied here (docs/theory.md 4.11), so seed k is the same bonded block
in every variant and knobs are compared by paired differences over seeds.

Parts:
  rate   inertial number I in {1e-2, 3.3e-3, 1e-3, 3.3e-4} (30x below the paper's 1e-2), each with
         penetration-stage local damping 0.7 and 0.1 (docs/theory.md 7.6)
  dt     dem.dt_safety 0.8 / 0.4 / 0.2 at the chosen rate (--rate, 1e-3) and damping (--damping, 0.1)
  damping  penetration damping 0.05 and 0 against the protocol's 0.1 at the chosen rate
  box    the coupled model against DEM everywhere, at the chosen rate and damping, at upscaling 1.5
         in a 4 x 4 x 4 mm outer box: the DEM-only box (replication 2 x 2 x 4 of the 2 x 2 x 1 mm
         REV, box of walls), and a DEM block of 2 x 2 x 2 mm and of 2 x 2 x 3 mm in the FDM
         continuum. Seed k is the same REV in every arm (replicated differently), so the arms are
         compared by paired differences against the DEM box.
  wide   the same comparison under the paper scenes' footing (D_f = 1.2 mm, about seven grains
         across, at the paper scenes' protocol rate I = 7.5e-4 and the chosen damping) in a
         6 x 6 x 4 mm outer box: DEM everywhere (replication 3 x 3 x 4, about 34,000 balls)
         against DEM blocks of 2 x 2 x 2, 4 x 4 x 2 and 4 x 4 x 3 mm (1.7 and 3.3 D_f wide, 1.7
         and 2.5 D_f deep) in the FDM continuum.

run: checks every planned run with the coordinator (coordinator SCENE --check --set ...; a bad
one: its error line, exit 2, nothing runs), then runs the variants' missing seeds (a finished seed
folder is kept: an interrupted study resumes), up to J runs at once, each as launch/run SCENE
--set ... Each seed's specimen and gravity equilibrium are computed once per group of variants
that differ only in their penetration stage: the first run of a group goes from scratch, the
others branch from its latest stage-end checkpoint they may start from (launch/run --from,
docs/checkpoint-format.md; the coordinator's --check with the run's overrides decides), which
gives the same bits as a run from scratch and saves the preparation (--no-branch: every run from
scratch). table: tables and figures (convergence_tables.md, converge_seeds.csv, converge_rate.png,
converge_dt.png in the study folder). list: the variants, their scenes and overrides (--check:
each variant and seed checked by the coordinator; nothing runs).
"""
import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import branching  # noqa: E402  (which saved state a run may start from)
import ensemble  # noqa: E402  (runs of an ensemble folder, statistics with t-based intervals)
import overrides  # noqa: E402  (scene variants as launch/run --set overrides)

BASE_SCENE = "scenes/accuracy_footing.toml"
# DEM everywhere (the box part's reference): the footing problem without its continuum, in a box
# of walls; an override sets keys, it cannot remove the [continuum] and [coupling] sections.
BOX_SCENE = "scenes/accuracy_footing_box.toml"
RATES = ["1e-2", "3.3e-3", "1e-3", "3.3e-4"]
# The wide part: the paper scenes' footing and protocol rate (docs/convergence.md, chosen protocol)
# over DEM blocks (width, width, depth) in mm of the 2 x 2 x 1 mm REV, in a 6 x 6 x 4 mm outer box.
WIDE_RATE = "7.5e-4"
WIDE_FOOTING = ["dem.footing.diameter=1.2e-3", "dem.footing.height=0.6e-3"]
WIDE_OUTER = (6, 6, 4)
WIDE_BLOCKS = [(2, 2), (4, 2), (4, 3)]
DAMPINGS = ["0.7", "0.1"]
STEPS = ["0.8", "0.4", "0.2"]


def rate_variant(rate, damping):
    return "rate_I%s_a%s" % (rate, damping)


def box_variant(arm, rate, damping):
    return "box_%s_I%s_a%s" % (arm, rate, damping)


def wide_variant(arm, damping):
    return "wide_%s_a%s" % (arm, damping)


def wide_arm(w, h):
    return "coupled%dx%dx%d" % (w, w, h)


def penetration(rate, damping, steps):
    """The overrides of the penetration stage: inertial number, local damping, step budget."""
    return [overrides.stage_set("penetrate", "inertial_number", rate), overrides.stage_set("penetrate", "damping", damping),
            overrides.stage_set("penetrate", "steps", steps)]


def plan(parts, rate, damping, quick):
    """[(variant name, part, label, scene (relative to the repository), overrides)] in the order
    they run (cheapest first)."""
    out = []
    if "rate" in parts:
        for r in RATES:
            for a in DAMPINGS:
                # The budget grows with the stroke time; the stage ends at depth_ratio.
                steps = int(40000 * 1e-2 / float(r) * 2)
                out.append((rate_variant(r, a), "rate", "I %s, damping %s" % (r, a), BASE_SCENE,
                            penetration(r, a, steps)))
    if "dt" in parts:
        for f in STEPS:
            steps = int(40000 * 1e-2 / float(rate) * 2 * 0.8 / float(f))
            sets = penetration(rate, damping, steps)
            name = "dt_%s_I%s_a%s" % (f, rate, damping)
            if f == "0.8":
                name = rate_variant(rate, damping)  # the same runs as the rate part's
            else:
                sets.append("dem.dt_safety=%s" % f)
            out.append((name, "dt", "dt_safety %s" % f, BASE_SCENE, sets))
    if "damping" in parts:
        # Below the protocol's damping: 0.05 and 0 against 0.1 (rate_variant(rate, "0.1")).
        steps = int(40000 * 1e-2 / float(rate) * 2)
        for a in ("0.1", "0.05", "0"):
            out.append((rate_variant(rate, a), "damping", "damping %s" % a, BASE_SCENE, penetration(rate, a, steps)))
    if "box" in parts:
        steps = int(40000 * 1e-2 / float(rate) * 2)
        pen = penetration(rate, damping, steps)
        out.append((box_variant("dem", rate, damping), "box", "DEM everywhere (4 x 4 x 4 mm box)", BOX_SCENE, pen))
        for h in (2, 3):
            out.append((box_variant("coupled%d" % h, rate, damping), "box", "DEM block 2 x 2 x %d mm in FDM" % h,
                        BASE_SCENE, ["continuum.mesh.size=[4e-3, 4e-3, 4e-3]"] + pen +
                        ["dem.specimen.replicate=[1, 1, %d]" % h, "continuum.mesh.inner_size=[2e-3, 2e-3, %de-3]" % h]))
    if "wide" in parts:
        steps = int(40000 * 1e-2 / float(WIDE_RATE) * 2)
        pen = penetration(WIDE_RATE, damping, steps) + WIDE_FOOTING
        ox, oy, oz = WIDE_OUTER
        for w, h in WIDE_BLOCKS:
            out.append((wide_variant(wide_arm(w, h), damping), "wide", "DEM block %d x %d x %d mm in FDM" % (w, w, h),
                        BASE_SCENE, ["continuum.mesh.size=[%de-3, %de-3, %de-3]" % WIDE_OUTER] + pen +
                        ["dem.specimen.replicate=[%d, %d, %d]" % (w // 2, w // 2, h),
                         "continuum.mesh.inner_size=[%de-3, %de-3, %de-3]" % (w, w, h)]))
        # The reference last: it costs about as much as the three coupled arms together.
        out.append((wide_variant("dem", damping), "wide", "DEM everywhere (%d x %d x %d mm box)" % WIDE_OUTER, BOX_SCENE,
                    pen + ["dem.specimen.replicate=[%d, %d, %d]" % (ox // 2, oy // 2, oz)]))
    if quick:
        out = [(n, p, lab, sc, s + [overrides.stage_set("penetrate", "depth_ratio", "0.05")])
               for n, p, lab, sc, s in out]
    seen, uniq = set(), []
    for v in out:
        if v[0] not in seen:
            seen.add(v[0])
            uniq.append(v)
    return uniq


finished = branching.finished


def seed_sets(root, scene, sets, seed):
    """The overrides of one seed's run: the variant's, run.seed, and no traffic log unless the
    scene says traffic_log."""
    return overrides.quiet_traffic(os.path.join(root, scene), list(sets) + ["run.seed=%d" % seed])


def check_jobs(root, jobs):
    """Every (variant, scene, sets, seed) job checked by the coordinator: [error lines]."""
    bad = []
    for name, scene, sets, seed in jobs:
        ok, msg = overrides.check(os.path.join(root, scene), seed_sets(root, scene, sets, seed))
        if not ok:
            bad.append("%s seed %d: %s" % (name, seed, msg))
    return bad


def run_one(root, study, variant, scene, sets, seed, branch=True, launcher=None):
    vdir = os.path.join(study, variant)
    os.makedirs(vdir, exist_ok=True)
    run_dir = os.path.join(vdir, "seed-%d" % seed)
    if finished(run_dir):
        return (variant, seed, 0, "kept")
    # One runner per seed folder, also across concurrent study commands on one folder.
    lock = os.path.join(vdir, "seed-%d.lock" % seed)
    try:
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return (variant, seed, 0, "running elsewhere (%s)" % lock)
    try:
        return run_locked(root, study, variant, scene, sets, seed, vdir, run_dir, branch, launcher)
    finally:
        os.remove(lock)


def branch_source(study, scene, sets, seed):
    """The stage-end checkpoint of a finished run of this seed in the study that the variant's
    scene with its overrides may start from (launch/py/branching.py: the coordinator decides),
    or None."""
    try:
        with open(os.path.join(study, "plan.json")) as f:
            variants = json.load(f)["variants"]
    except (OSError, ValueError, KeyError):
        return None
    runs = [os.path.join(study, v["name"], "seed-%d" % seed) for v in variants]
    return branching.branch_source(branching.coordinator_command() + overrides.set_args(sets), scene, runs)


def run_locked(root, study, variant, scene, sets, seed, vdir, run_dir, branch=True, launcher=None):
    if os.path.exists(run_dir):  # an interrupted or failed run: keep it under another name
        os.rename(run_dir, run_dir + ".failed-%d" % int(time.time()))
    path = os.path.join(root, scene)
    sets = seed_sets(root, scene, sets, seed)
    source = branch_source(study, path, sets, seed) if branch else None
    t0 = time.time()
    with open(os.path.join(vdir, "seed-%d.out" % seed), "w") as out:
        code = subprocess.call(([launcher] if launcher else ["bash", os.path.join(root, "launch/run")]) +
                               [path, "--no-build"] + overrides.set_args(sets) +
                               ["--run-dir", run_dir] + (["--from", source] if source else []),
                               stdout=out, stderr=subprocess.STDOUT)
    how = "%.0f s" % (time.time() - t0) + (", branched from %s" % os.path.relpath(source, study) if source else "")
    return (variant, seed, code, how)


def cmd_run(a):
    root = os.environ["DEMFDM_ROOT"]
    variants = plan(a.parts, a.rate, a.damping, a.quick)
    jobs = [(n, sc, s, k) for n, _, _, sc, s in variants for k in range(1, a.seeds + 1) if not a.only or n in a.only]
    bad = check_jobs(root, jobs)
    if bad:
        print("converge study: the coordinator refuses %d run(s); nothing runs:\n  %s" % (len(bad), "\n  ".join(bad)),
              file=sys.stderr)
        return 2
    os.makedirs(a.study, exist_ok=True)
    meta = {"base_scene": BASE_SCENE, "seeds": a.seeds, "parts": a.parts, "rate": a.rate, "damping": a.damping,
            "quick": a.quick, "variants": [{"name": n, "part": p, "label": lab, "scene": sc, "set": s}
                                           for n, p, lab, sc, s in variants]}
    path = os.path.join(a.study, "plan.json")
    if os.path.isfile(path):  # extend: keep the variants already planned
        with open(path) as f:
            old = json.load(f)
        names = {v["name"] for v in meta["variants"]}
        meta["variants"] = [v for v in old["variants"] if v["name"] not in names] + meta["variants"]
        meta["parts"] = sorted(set(old["parts"]) | set(a.parts))
    with open(path, "w") as f:
        json.dump(meta, f, indent=1)
    failed = []
    with ThreadPoolExecutor(max_workers=a.jobs) as pool:
        for variant, seed, code, how in pool.map(
                lambda j: run_one(root, a.study, *j, branch=not a.no_branch, launcher=a.launcher), jobs):
            print("converge study: %s seed %d: %s (exit %d)" % (variant, seed, how, code), file=sys.stderr, flush=True)
            if code != 0:
                failed.append("%s seed %d (exit %d, output %s/%s/seed-%d.out)" % (variant, seed, code, a.study, variant, seed))
    if failed:
        print("converge study: failed runs:\n  " + "\n  ".join(failed), file=sys.stderr)
        return 1
    return 0


def cmd_list(a):
    root = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    variants = plan(a.parts, a.rate, a.damping, a.quick)
    for n, part, label, scene, sets in variants:
        print("%-28s %-7s %-34s launch/run %s" % (n, part, label, shlex.join(
            [scene] + overrides.set_args(seed_sets(root, scene, sets, 1)))))
    if not a.check:
        return 0
    bad = check_jobs(root, [(n, sc, s, k) for n, _, _, sc, s in variants for k in range(1, a.seeds + 1)])
    for b in bad:
        print("converge study: refused: %s" % b, file=sys.stderr)
    print("converge study: %d variant(s) x %d seed(s) checked by the coordinator, %d refused" %
          (len(variants), a.seeds, len(bad)), file=sys.stderr)
    return 2 if bad else 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("study")
    ls = sub.add_parser("list")
    for q in (r, ls):
        q.add_argument("--parts", nargs="+", default=["rate", "dt"], choices=["rate", "dt", "box", "damping", "wide"])
        q.add_argument("--seeds", type=int, default=5)
        q.add_argument("--rate", default="1e-3")
        q.add_argument("--damping", default="0.1")
        q.add_argument("--quick", action="store_true")
    r.add_argument("--jobs", type=int, default=1)
    r.add_argument("--only", nargs="+", help="run only these variants (names as in 'list')")
    r.add_argument("--no-branch", action="store_true", help="run every variant from scratch (no --from)")
    r.add_argument("--launcher", help=argparse.SUPPRESS)  # tests: a stand-in for launch/run
    ls.add_argument("--check", action="store_true", help="check every variant and seed with the coordinator")
    t = sub.add_parser("table")
    t.add_argument("study")
    a = p.parse_args()
    if a.cmd == "run":
        return cmd_run(a)
    if a.cmd == "list":
        return cmd_list(a)
    return cmd_table(a)


INTERVALS = 4
MEASURES = [("mean_load_all", "mean load over the stroke"), ("q1", "mean load, 1st quarter"),
            ("q2", "mean load, 2nd quarter"), ("q3", "mean load, 3rd quarter"), ("q4", "mean load, 4th quarter"),
            ("peak", "raw peak")]


def dem_stage_values(run, stage):
    """The values of the DEM's end-of-stage line of `stage` in dem.log (energies, bonds)."""
    out = {}
    with open(os.path.join(run, "dem.log")) as f:
        for line in f:
            if "'%s' ends after step" % stage in line and "values:" in line:
                for kv in line.split("values:")[1].split():
                    k, _, v = kv.partition("=")
                    try:
                        out[k] = float(v)
                    except ValueError:
                        pass
    return out


def kinetic_share(run, r):
    """Kinetic energy of the DEM over the work the footing has done, at the end of the stroke and
    its largest value over the second half (dem_history.csv joined with the stage history)."""
    path = os.path.join(run, "dem_history.csv")
    if not os.path.exists(path):
        return float("nan"), float("nan")
    h = ensemble.paper_figures.read_csv(path)
    st = r["hist"]
    d, f = st["dem.footing_disp_m"], st["dem.footing_fz_N"]
    work = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(d))])
    ke = np.interp(st["step"], h["step_unit"], h["kinetic_J"])
    half = d >= 0.5 * d[-1]
    share = np.where(work > 0, ke / np.where(work > 0, work, 1.0), np.nan)
    return float(share[-1]), float(np.nanmax(share[half])) if half.any() else float("nan")


def run_cpu_s(run):
    """CPU seconds of a run: the cpu_s of every stage end in the nodes' logs, summed."""
    total = 0.0
    for name in ("dem.log", "continuum.log"):
        path = os.path.join(run, name)
        if not os.path.exists(path):
            continue
        with open(path) as f:
            for line in f:
                if "values:" in line and " ends after step " in line:
                    for kv in line.split("values:")[1].split():
                        if kv.startswith("cpu_s="):
                            total += float(kv[6:])
    return total


def seed_metrics(variant_dir, edges):
    """{seed: {measure: value}} of the finished runs of one variant."""
    out = {}
    for r in ensemble.load_runs(variant_dir):
        d, f = r["disp"], r["load"]
        q = ensemble.interval_means(d, f, edges)
        m = {"mean_load_all": ensemble.interval_means(d, f, [edges[0], edges[-1]])[0], "peak": float(np.max(f)),
             "k_e": r["k_e"], "wall_s": r["wall_s"]}
        for i, v in enumerate(q):
            m["q%d" % (i + 1)] = v
        ev = dem_stage_values(r["path"], "penetrate")
        m["energy_balance_error"] = ev.get("energy_balance_error", float("nan"))
        m["ke_share_end"], m["ke_share_max"] = kinetic_share(r["path"], r)
        m["bonds_broken"] = ev.get("bonds_broken_tension", 0) + ev.get("bonds_broken_shear", 0)
        m["cpu_s"] = run_cpu_s(r["path"])
        out[r["seed"]] = (m, r)
    return out


def paired(a, b, key):
    """ensemble.paired_verdict of one measure of two variants' seed metrics."""
    return ensemble.paired_verdict({k: v[0][key] for k, v in a.items()}, {k: v[0][key] for k, v in b.items()})


def fmt(v, spec=".4g"):
    return "n/a" if v is None or not np.isfinite(v) else format(v, spec)


def stat_cell(vals, spec=".4g"):
    mean, se, half, n = ensemble.scalar_stats(vals)
    return "%s ± %s" % (fmt(mean, spec), fmt(half, ".2g"))


def band_figure(path, title, groups, grid):
    """One panel per group: [(panel title, [(label, runs)])]: mean curves with 95 % bands."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(groups), figsize=(6.2 * len(groups), 4.6), squeeze=False)
    for ax, (ptitle, series) in zip(axes[0], groups):
        for label, runs in series:
            if not runs:
                continue
            cs = ensemble.curve_stats(runs, grid)
            line, = ax.plot(grid * 1e3, cs["mean"], lw=1.6, label="%s (n = %d)" % (label, cs["n"]))
            ax.fill_between(grid * 1e3, cs["low"], cs["high"], color=line.get_color(), alpha=0.18, lw=0)
        ax.set_xlabel("footing displacement [mm]")
        ax.set_ylabel("footing load [N]")
        ax.set_title(ptitle)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def cmd_table(a):
    with open(os.path.join(a.study, "plan.json")) as f:
        meta = json.load(f)
    variants = {v["name"]: v for v in meta["variants"]}
    present = {n: os.path.join(a.study, n) for n in variants if os.path.isdir(os.path.join(a.study, n))}
    # Common stroke: from 0 to the smallest final displacement of every run; the wide part (another
    # footing, a longer stroke) has its own.
    runs = {n: ensemble.load_runs(d) for n, d in present.items()}

    def stroke_of(names):
        rs = [r for n in names for r in runs[n]]
        if not rs:
            return None
        lo, hi = max(float(r["disp"][0]) for r in rs), min(float(r["disp"][-1]) for r in rs)
        return list(np.linspace(lo, hi, INTERVALS + 1)), np.linspace(lo, hi, 300)

    wide = [n for n in present if variants[n]["part"] == "wide"]
    narrow = [n for n in present if n not in wide]
    if not any(runs.values()):
        raise SystemExit("converge study: no finished run in %s" % a.study)
    edges, grid = stroke_of(narrow) or stroke_of(wide)
    wedges, wgrid = stroke_of(wide) or (edges, grid)
    stroke = edges[-1]
    met = {n: seed_metrics(d, wedges if n in wide else edges) for n, d in present.items()}
    md = ["# Convergence study: tables", "",
          "Study folder `%s`; base scene `%s`; %d seeds planned. Every variant runs seeds 1..N on the same bonded "
          "blocks (specimen preparation does not depend on the knobs varied, docs/theory.md 4.11), so knobs are "
          "compared by the paired difference over seeds: mean ± half-width of its 95 %% confidence interval "
          "(Student t), relative to the reference's seed mean. \"not resolved\" = the interval holds 0. Loads are "
          "means over the common stroke 0 to %.4g mm (%d equal intervals), a robust measure beside the raw peak."
          % (a.study, meta["base_scene"], meta["seeds"], stroke * 1e3, INTERVALS) +
          (" The wide part's loads are over its own common stroke, 0 to %.4g mm." % (wedges[-1] * 1e3) if wide and narrow
           else ""), ""]
    rows = [["variant", "n", "mean load [N]", "q1 [N]", "q2 [N]", "q3 [N]", "q4 [N]", "raw peak [N]", "k_e [N/m]",
             "KE/W end", "KE/W max (2nd half)", "energy balance error", "bonds broken", "wall [s]"]]
    for n in variants:
        if n not in met or not met[n]:
            continue
        m = [v[0] for v in met[n].values()]
        col = lambda k, spec=".4g": stat_cell([x[k] for x in m], spec)  # noqa: E731
        rows.append([n, str(len(m)), col("mean_load_all"), col("q1"), col("q2"), col("q3"), col("q4"), col("peak"),
                     col("k_e", ".3g"), col("ke_share_end", ".2g"), col("ke_share_max", ".2g"),
                     col("energy_balance_error", ".2g"), col("bonds_broken", ".4g"), col("wall_s", ".3g")])
    md += ["## Every variant (seed mean ± 95 % CI)", ""] + table_md(rows)
    csv_rows = [["variant", "seed", "measure", "value"]]
    for n in met:
        for seed, (m, _) in sorted(met[n].items()):
            for k, v in sorted(m.items()):
                csv_rows.append([n, str(seed), k, repr(v)])
    with open(os.path.join(a.study, "converge_seeds.csv"), "w") as f:
        f.write("\n".join(",".join(r) for r in csv_rows) + "\n")
    figures = []
    if "rate" in meta["parts"]:
        md += rate_tables(met, variants)
        groups = [("penetration damping %s" % dmp, [("I = %s" % r, runs.get(rate_variant(r, dmp), [])) for r in RATES])
                  for dmp in DAMPINGS]
        band_figure(os.path.join(a.study, "converge_rate.png"), "Footing load, seed mean and 95 % band, by rate", groups,
                    grid)
        figures.append("converge_rate.png")
    if "dt" in meta["parts"]:
        md += dt_tables(met, meta)
        names = [n for n, v in variants.items() if v["part"] == "dt"]
        band_figure(os.path.join(a.study, "converge_dt.png"), "Footing load, seed mean and 95 % band, by DEM step",
                    [("I %s, damping %s" % (meta["rate"], meta["damping"]),
                      [(variants[n]["label"], runs.get(n, [])) for n in names])], grid)
        figures.append("converge_dt.png")
    if "damping" in meta["parts"]:
        md += damping_tables(met, meta)
        names = [rate_variant(meta["rate"], a) for a in ("0.1", "0.05", "0")]
        band_figure(os.path.join(a.study, "converge_damping.png"), "Footing load, seed mean and 95 % band, by damping",
                    [("I %s" % meta["rate"], [("damping %s" % n.rsplit("_a", 1)[1], runs.get(n, [])) for n in names])],
                    grid)
        figures.append("converge_damping.png")
    if "box" in meta["parts"]:
        md += box_tables(met, meta)
        names = [n for n, v in variants.items() if v["part"] == "box"]
        band_figure(os.path.join(a.study, "converge_box.png"),
                    "Footing load, seed mean and 95 % band: coupled against DEM everywhere",
                    [("I %s, damping %s, 4 mm outer box" % (meta["rate"], meta["damping"]),
                      [(variants[n]["label"], runs.get(n, [])) for n in names])], grid)
        figures.append("converge_box.png")
    if "wide" in meta["parts"]:
        md += wide_tables(met, meta)
        names = [n for n, v in variants.items() if v["part"] == "wide"]
        if wide:
            band_figure(os.path.join(a.study, "converge_wide.png"),
                        "Coupled vs DEM everywhere, D_f = 1.2 mm: mean, 95 % band",
                        [("I %s, damping %s, %d x %d x %d mm outer box" % ((WIDE_RATE, meta["damping"]) + WIDE_OUTER),
                          [(variants[n]["label"], runs.get(n, [])) for n in names])], wgrid)
            figures.append("converge_wide.png")
    md += ["", "Figures: " + ", ".join("`%s`" % x for x in figures), ""]
    text = "\n".join(md) + "\n"
    with open(os.path.join(a.study, "convergence_tables.md"), "w") as f:
        f.write(text)
    print(text)
    return 0


def table_md(rows):
    out = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    out += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    return out + [""]


def rate_tables(met, variants):
    md = ["## Rate: each rate against the slowest, same damping (paired over seeds)", ""]
    slow = RATES[-1]
    rows = [["damping", "I"] + [lab for _, lab in MEASURES]]
    for dmp in DAMPINGS:
        ref = met.get(rate_variant(slow, dmp))
        for r in RATES[:-1]:
            cur = met.get(rate_variant(r, dmp))
            if not ref or not cur:
                continue
            rows.append([dmp, r] + [paired(cur, ref, k) for k, _ in MEASURES])
    md += table_md(rows)
    md += ["## Damping: penetration damping 0.7 against 0.1 at each rate (paired over seeds)", ""]
    rows = [["I"] + [lab for _, lab in MEASURES]]
    for r in RATES:
        hi, lo = met.get(rate_variant(r, DAMPINGS[0])), met.get(rate_variant(r, DAMPINGS[1]))
        if hi and lo:
            rows.append([r] + [paired(hi, lo, k) for k, _ in MEASURES])
    return md + table_md(rows)


def dt_tables(met, meta):
    md = ["## DEM step: dt_safety 0.4 and 0.2 against 0.8 at I %s, damping %s (paired over seeds)"
          % (meta["rate"], meta["damping"]), ""]
    ref = met.get(rate_variant(meta["rate"], meta["damping"]))
    rows = [["dt_safety"] + [lab for _, lab in MEASURES]]
    for f in STEPS[1:]:
        cur = met.get("dt_%s_I%s_a%s" % (f, meta["rate"], meta["damping"]))
        if ref and cur:
            rows.append([f] + [paired(cur, ref, k) for k, _ in MEASURES])
    return md + table_md(rows)


def damping_tables(met, meta):
    md = ["## Damping below the protocol's: 0.05 and 0 against 0.1 at I %s (paired over seeds)" % meta["rate"], ""]
    ref = met.get(rate_variant(meta["rate"], "0.1"))
    rows = [["damping"] + [lab for _, lab in MEASURES]]
    for a in ("0.05", "0"):
        cur = met.get(rate_variant(meta["rate"], a))
        if ref and cur:
            rows.append([a] + [paired(cur, ref, k) for k, _ in MEASURES])
    return md + table_md(rows)


def box_tables(met, meta):
    md = ["## Coupled against DEM everywhere: each coupled arm against the DEM box, I %s, damping %s "
          "(paired over seeds)" % (meta["rate"], meta["damping"]), ""]
    ref = met.get(box_variant("dem", meta["rate"], meta["damping"]))
    rows = [["arm"] + [lab for _, lab in MEASURES]]
    for h in (2, 3):
        cur = met.get(box_variant("coupled%d" % h, meta["rate"], meta["damping"]))
        if ref and cur:
            rows.append(["DEM block 2 x 2 x %d mm" % h] + [paired(cur, ref, k) for k, _ in MEASURES])
    return md + table_md(rows)


def wide_tables(met, meta):
    md = ["## Coupled against DEM everywhere under the paper's footing (D_f = 1.2 mm): each coupled arm against "
          "the DEM box, I %s, damping %s (paired over seeds)" % (WIDE_RATE, meta["damping"]), ""]
    ref = met.get(wide_variant("dem", meta["damping"]))
    rows = [["arm"] + [lab for _, lab in MEASURES] + ["k_e", "CPU time (both nodes)", "CPU: DEM box / arm"]]
    ref_cpu = np.mean([v[0]["cpu_s"] for v in ref.values()]) if ref else float("nan")
    for w, h in WIDE_BLOCKS:
        cur = met.get(wide_variant(wide_arm(w, h), meta["damping"]))
        if ref and cur:
            cpu = np.mean([v[0]["cpu_s"] for v in cur.values()])
            rows.append(["DEM block %d x %d x %d mm" % (w, w, h)] + [paired(cur, ref, k) for k, _ in MEASURES] +
                        [paired(cur, ref, "k_e"), paired(cur, ref, "cpu_s"), fmt(ref_cpu / cpu, ".3g")])
    md += table_md(rows)
    md += ["CPU time: the nodes' cpu_s summed over every stage (preparation included), seed mean; the DEM "
           "box's is %s s." % fmt(ref_cpu, ".4g"), ""]
    return md


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""Seed ensembles of one scene (issue 12 item 5): run a scene over N generator seeds, then report
the footing curve as a mean with a 95 % band and the scalar measures with confidence intervals.

Usage:
  /usr/bin/python3 launch/py/ensemble.py run ENSEMBLE_DIR --scene SCENE --seeds SPEC [--jobs J]
      [--set table.key=value ...] [--stage-set stage.key=value ...] [--check]
  /usr/bin/python3 launch/py/ensemble.py table ENSEMBLE_DIR [--stage penetrate] [--intervals 4]
  (launch/run SCENE --seeds SPEC [--jobs J] does both.)

run: SPEC is N (seeds 1..N), A-B (seeds A..B) or a comma list of seeds and ranges (1,4,7-9).
Seed k runs `launch/run SCENE --no-build --set ... --run-dir ENSEMBLE_DIR/seed-<k>` (output in
seed-<k>.log), at most J runs at once (default 1). Its overrides (seed_sets): the --set ones
(table.key=value, as launch/run --set takes them), the --stage-set ones (stage.key=value, the
same as --set stage.STAGE.key=value), run.seed=k, and output.traffic_log=false unless the scene or
an override says traffic_log (a traffic log per seed would take about 1 GB for the default
scene). The scene file is never edited: each run records its effective scene as
seed-<k>/scene.toml. Every seed's overrides are checked (launch/run SCENE --check --set ...)
before anything starts (--check: only that). A seed whose folder holds a finished run
(summary.json, summary.txt not "FAILED") is not run again, so an interrupted ensemble resumes; an
unfinished folder is kept as seed-<k>.incomplete-<i> and the seed runs again. A finished seed run
with other values in effect than the scene with the seed's overrides (compared through the
coordinator, so a folder written before ensembles used overrides counts as well) is an error
(use a new folder). A failed run is named with its exit code and the last lines of its output;
the command exits 3 after the other runs have finished (2: bad arguments or scene, 130:
interrupted).

table: reads every finished ENSEMBLE_DIR/seed-<k>/ run and writes
  ensemble.csv        the mean curve: displacement grid, mean load, sd, standard error, 95 % band
                      (pointwise confidence interval of the mean), n;
  ensemble_stats.csv  one row per measure: n, mean, se, 95 % CI half-width and limits, each seed;
  ensemble.md         the same tables for people, with the method;
  ensemble.png        every seed's curve, the mean and the band.
Measures per seed: raw peak load (maximum of the spiky load signal) and its displacement, k_e
(paper_figures.elastic_stiffness: slope before the first bond failure), k50
(paper_figures.initial_stiffness), the mean load over each of `intervals` equal stroke intervals
of the common displacement range and over the whole range (robust against single spikes), and
the run's wall time (summary.json). Curves are put on a common displacement grid by linear
interpolation, over the range that every seed reaches.
Confidence intervals: mean +- t(0.975, n-1) se, se = sd / sqrt(n) (sample sd, n-1).

Library: load_runs(dir), common_grid(runs), curve_stats(runs, grid), scalar_stats(values),
interval_means(disp, load, edges), t975(dof), parse_seeds(spec), seed_sets(scene, seed, ...).
"""
import argparse
import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import tomllib

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import paper_figures  # noqa: E402  (read_csv, initial_stiffness, elastic_stiffness, history_path)
import branching  # noqa: E402  (stop_runs, coordinator_command)
import overrides  # noqa: E402  (scene variants as launch/run --set overrides)

ROOT = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
SEED_DIR = re.compile(r"^seed-(\d+)$")
DISP, LOAD = "dem.footing_disp_m", "dem.footing_fz_N"

# Student-t 0.975 quantiles (two-sided 95 %) for 1..30 degrees of freedom.
T975 = [12.706204736, 4.302652730, 3.182446305, 2.776445105, 2.570581836, 2.446911851, 2.364624252,
        2.306004135, 2.262157163, 2.228138852, 2.200985160, 2.178812830, 2.160368656, 2.144786688,
        2.131449546, 2.119905299, 2.109815578, 2.100922040, 2.093024054, 2.085963447, 2.079613845,
        2.073873068, 2.068657610, 2.063898562, 2.059538553, 2.055529439, 2.051830516, 2.048407142,
        2.045229642, 2.042272456]
Z975 = 1.959963984540054  # the normal 0.975 quantile


def t975(dof):
    """Student-t 0.975 quantile for dof degrees of freedom: the table up to 30; beyond, the normal
    value with the Cornish-Fisher terms in 1/dof (Abramowitz & Stegun 26.7.5; error < 1e-6 there;
    the bare normal value would be 4 % low at 31 dof). NaN for dof < 1."""
    if not dof >= 1:
        return float("nan")
    if dof <= 30:
        return T975[int(dof) - 1]
    z, v = Z975, float(dof)
    g1 = (z ** 3 + z) / 4
    g2 = (5 * z ** 5 + 16 * z ** 3 + 3 * z) / 96
    g3 = (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / 384
    g4 = (79 * z ** 9 + 776 * z ** 7 + 1482 * z ** 5 - 1920 * z ** 3 - 945 * z) / 92160
    return z + g1 / v + g2 / v ** 2 + g3 / v ** 3 + g4 / v ** 4


def scalar_stats(values):
    """(mean, standard error, half-width of the 95 % confidence interval of the mean, n) of the
    finite values (NaNs, e.g. a stiffness a run could not give, are left out and not counted).
    se = sample sd (n-1) / sqrt(n); half = t975(n-1) se; se and half are NaN for n < 2."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    n = len(v)
    if n == 0:
        return float("nan"), float("nan"), float("nan"), 0
    mean = float(v.mean())
    if n < 2:
        return mean, float("nan"), float("nan"), 1
    se = float(v.std(ddof=1) / math.sqrt(n))
    return mean, se, t975(n - 1) * se, n


def paired_verdict(a, b):
    """Paired comparison of two settings run on the same seeds: a, b = {seed: value}. Returns
    'not resolved (+x ± y %)' when the 95 % interval of the mean of a_k - b_k over the seeds both
    have contains 0, else 'differs (+x ± y %)', relative to the mean of b over those seeds; 'n/a'
    with fewer than two common seeds."""
    seeds = sorted(set(a) & set(b))
    mean, _, half, _ = scalar_stats([a[s] - b[s] for s in seeds])
    return verdict(mean, half, scalar_stats([b[s] for s in seeds])[0])


def verdict(diff, half, ref):
    """The words of a difference `diff` with a 95 % half-width `half` relative to `ref`."""
    if not (np.isfinite(diff) and np.isfinite(half)) or ref == 0:
        return "n/a"
    word = "not resolved" if abs(diff) <= half else "differs"
    x, h = 100 * diff / ref, 100 * half / abs(ref)
    if max(abs(x), h) >= 1:
        return "%s (%+.1f ± %.1f %%)" % (word, x, h)
    return "%s (%+.2g ± %.2g %%)" % (word, x, h)  # below 1 %: two significant digits


def interval_means(disp, load, edges):
    """Mean load over each interval [edges[i], edges[i+1]] of displacement: the integral of the
    piecewise-linear load(disp) over the interval divided by its length (trapezoids, the ends
    interpolated), i.e. weighted by stroke, not by sample (samples are denser where the footing
    moves slowly). disp must be increasing; intervals outside the curve give NaN."""
    d, f = np.asarray(disp, dtype=float), np.asarray(load, dtype=float)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        if not (b > a) or a < d[0] or b > d[-1]:
            out.append(float("nan"))
            continue
        inner = (d > a) & (d < b)
        x = np.concatenate(([a], d[inner], [b]))
        y = np.concatenate(([np.interp(a, d, f)], f[inner], [np.interp(b, d, f)]))
        out.append(float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)) / (b - a)))
    return out


def _curve(r):
    return (r["disp"], r["load"]) if isinstance(r, dict) else (np.asarray(r[0], float), np.asarray(r[1], float))


def common_grid(runs, points=None):
    """Displacement grid over the range every curve reaches (largest start to smallest end); by
    default with as many points as the sparsest curve has samples in that range (at least 2)."""
    curves = [_curve(r) for r in runs]
    lo = max(float(d[0]) for d, _ in curves)
    hi = min(float(d[-1]) for d, _ in curves)
    if not hi > lo:
        raise ValueError("the curves share no displacement range (%.4g to %.4g m)" % (lo, hi))
    if points is None:
        points = max(2, min(int(np.count_nonzero((d >= lo) & (d <= hi))) for d, _ in curves))
    return np.linspace(lo, hi, points)


def curve_stats(runs, grid):
    """Pointwise statistics of the curves (run dicts from load_runs, or (disp, load) pairs, disp
    increasing) interpolated linearly onto grid: dict of grid, mean, sd, se, half (95 % CI
    half-width of the mean), low, high (the band), n. For one curve sd, se, half are NaN and the
    band is the curve."""
    ys = np.array([np.interp(grid, *_curve(r)) for r in runs])
    n = len(ys)
    mean = ys.mean(axis=0)
    if n > 1:
        sd = ys.std(axis=0, ddof=1)
        se = sd / math.sqrt(n)
        half = t975(n - 1) * se
    else:
        sd = se = half = np.full(len(grid), np.nan)
    band = np.nan_to_num(half)
    return {"grid": np.asarray(grid), "mean": mean, "sd": sd, "se": se, "half": half, "low": mean - band,
            "high": mean + band, "n": n, "curves": ys}


def run_finished(d):
    """A finished run folder: summary.json written and summary.txt not marked FAILED."""
    if not os.path.exists(os.path.join(d, "summary.json")):
        return False
    txt = os.path.join(d, "summary.txt")
    return not (os.path.exists(txt) and open(txt).read().startswith("FAILED"))


def seed_folders(ens):
    """{seed: folder} of ENSEMBLE_DIR/seed-<k>/ folders."""
    out = {}
    for name in os.listdir(ens):
        m = SEED_DIR.match(name)
        if m and os.path.isdir(os.path.join(ens, name)):
            out[int(m.group(1))] = os.path.join(ens, name)
    return dict(sorted(out.items()))


def stage_history(run, stage):
    files = sorted((f for f in os.listdir(run) if re.match(r"^history_\d+_%s\.csv$" % re.escape(stage), f)),
                   key=lambda f: int(f.split("_")[1]))
    if not files:
        raise ValueError("%s: no history_*_%s.csv (stage '%s' not run?)" % (run, stage, stage))
    return os.path.join(run, files[0])


def load_run(run, stage="penetrate"):
    """One finished run folder: dict of path, seed (from its scene), disp, load (sorted by
    displacement), hist (every column of the stage history), d_f (footing diameter, NaN without
    one), wall_s (summary.json), k_e (paper_figures.elastic_stiffness; NaN when the stage is not
    the penetration history paper_figures reads)."""
    path = stage_history(run, stage)
    h = paper_figures.read_csv(path)
    for c in (DISP, LOAD):
        if c not in h:
            raise ValueError("%s: no column %s" % (path, c))
    order = np.argsort(h[DISP], kind="stable")
    scene = {}
    if os.path.exists(os.path.join(run, "scene.toml")):
        with open(os.path.join(run, "scene.toml"), "rb") as f:
            scene = tomllib.load(f)
    d_f = float(scene.get("dem", {}).get("footing", {}).get("diameter", float("nan")))
    js = json.load(open(os.path.join(run, "summary.json")))
    k_e = float("nan")
    if os.path.abspath(paper_figures.history_path(run)) == os.path.abspath(path):
        k_e = paper_figures.elastic_stiffness(run)[0]
    return {"path": run, "seed": scene.get("run", {}).get("seed"), "disp": h[DISP][order], "load": h[LOAD][order],
            "hist": h, "d_f": d_f, "wall_s": float(js["totals"]["wall_s"]), "k_e": k_e}


def load_runs(ens, stage="penetrate", skipped=None):
    """Every finished seed-<k>/ run of ENSEMBLE_DIR (load_run dicts, by seed; "seed" is the folder's
    k). Unfinished or unreadable folders are left out, and (seed, reason) is appended to skipped
    when a list is given."""
    runs = []
    for k, d in seed_folders(ens).items():
        if not run_finished(d):
            txt = os.path.join(d, "summary.txt")
            why = open(txt).readline().strip() if os.path.exists(txt) else "no summary.json (not finished)"
            if skipped is not None:
                skipped.append((k, why))
            continue
        try:
            r = load_run(d, stage)
        except (OSError, ValueError, KeyError) as ex:
            if skipped is not None:
                skipped.append((k, str(ex)))
            continue
        r["seed"] = k
        runs.append(r)
    return runs


def measures(runs, edges):
    """[(key, label, unit, [value per run])] of the scalar measures."""
    out = [("peak_N", "raw peak load", "N", []), ("disp_at_peak_m", "displacement at the raw peak", "m", []),
           ("k_e_N_m", "k_e (elastic, before the first bond failure)", "N/m", []),
           ("k50_N_m", "k50 (rising branch to half the first peak)", "N/m", [])]
    n_int = len(edges) - 1
    for i in range(n_int):
        out.append(("mean_load_%d_N" % (i + 1), "mean load over stroke interval %d (%.4g to %.4g mm)"
                    % (i + 1, edges[i] * 1e3, edges[i + 1] * 1e3), "N", []))
    out.append(("mean_load_all_N", "mean load over the common stroke (%.4g to %.4g mm)" % (edges[0] * 1e3, edges[-1] * 1e3),
                "N", []))
    out.append(("wall_s", "run wall time", "s", []))
    for r in runs:
        d, f = r["disp"], r["load"]
        i = int(np.argmax(f))
        k50 = paper_figures.initial_stiffness(d, f, r["d_f"])[0] if np.isfinite(r["d_f"]) else float("nan")
        ints = interval_means(d, f, edges)
        vals = [float(f[i]), float(d[i]), r["k_e"], k50] + ints + [interval_means(d, f, [edges[0], edges[-1]])[0],
                                                                   r["wall_s"]]
        for m, v in zip(out, vals):
            m[3].append(v)
    return out


SHORT = {"peak_N": "peak", "disp_at_peak_m": "d at peak", "k_e_N_m": "k_e", "k50_N_m": "k50",
         "mean_load_all_N": "F all", "wall_s": "wall"}  # per-seed table headers (F<i>: interval i)


def _fmt(v, spec=".4g"):
    return "-" if v is None or not np.isfinite(v) else format(v, spec)


def table(ens, stage="penetrate", intervals=4):
    skipped = []
    runs = load_runs(ens, stage, skipped)
    for k, why in skipped:
        print("ensemble: seed %d not included: %s" % (k, why), file=sys.stderr)
    if not runs:
        print("ensemble: %s holds no finished seed-<k>/ run" % ens, file=sys.stderr)
        return 2
    meta = {}
    if os.path.exists(os.path.join(ens, "ensemble.json")):
        meta = json.load(open(os.path.join(ens, "ensemble.json")))
    scene = os.path.splitext(os.path.basename(meta.get("scene", "")))[0] or "scene"
    grid = common_grid(runs)
    cs = curve_stats(runs, grid)
    n = cs["n"]
    with open(os.path.join(ens, "ensemble.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["disp_m", "mean_load_N", "sd_N", "se_N", "band_low_N", "band_high_N", "n"])
        for row in zip(grid, cs["mean"], cs["sd"], cs["se"], cs["low"], cs["high"]):
            w.writerow(["%.9g" % x for x in row] + [n])
    edges = np.linspace(grid[0], grid[-1], intervals + 1)
    ms = measures(runs, edges)
    seeds = [r["seed"] for r in runs]
    stats = []
    with open(os.path.join(ens, "ensemble_stats.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["measure", "unit", "n", "mean", "se", "ci95_half", "ci95_low", "ci95_high"] +
                   ["seed_%d" % s for s in seeds])
        for key, label, unit, vals in ms:
            mean, se, half, m = scalar_stats(vals)
            stats.append((key, label, unit, vals, mean, se, half, m))
            w.writerow([key, unit, m] + ["%.9g" % x for x in (mean, se, half, mean - half, mean + half)] +
                       ["%.9g" % v for v in vals])
    scale = {"m": (1e3, "mm"), "N/m": (1.0, "N/m"), "N": (1.0, "N"), "s": (1.0, "s")}
    lines = ["# Seed ensemble: %s, n = %d" % (scene, n), ""]
    if meta:
        sets = meta.get("set", []) + ["stage." + e for e in meta.get("stage_set", [])]
        lines += ["Scene `%s`%s; stage `%s`; seeds %s." % (meta.get("scene"), (", overrides: " + ", ".join(
            "`--set %s`" % e for e in sets)) if sets else "", stage, ", ".join(map(str, seeds))), ""]
    else:
        lines += ["Stage `%s`; seeds %s." % (stage, ", ".join(map(str, seeds))), ""]
    if skipped:
        lines += ["Not included (not finished or unreadable): " + "; ".join("seed %d (%s)" % s for s in skipped) + ".", ""]
    lines += [
        "Method. Each seed's load-displacement curve (`%s` against `%s`) is put on a common grid of %d "
        "displacements by linear interpolation, over the range that all seeds reach (%.4g to %.4g mm); the "
        "band of `ensemble.csv` and `ensemble.png` is the pointwise 95 %% confidence interval of the mean load, "
        "mean +- t(0.975, n-1) se with se = sd / sqrt(n) (it narrows with more seeds; it is not the spread of "
        "single runs, which is sd). The scalar measures are computed on each seed's own curve and given as "
        "mean +- the same 95 %% half-width (t-distribution, n-1 degrees of freedom). The raw peak is the "
        "maximum of a spiky signal; the interval means (load integrated over displacement over %d equal "
        "intervals of the common range, divided by the interval length) are the robust measure. k_e: "
        "least-squares slope from the first contact to the last row before the first bond failure "
        "(paper_figures.elastic_stiffness); k50: slope of the rising branch to half the first peak "
        "(paper_figures.initial_stiffness). Wall time: the coordinator's clock (summary.json)."
        % (LOAD, DISP, len(grid), grid[0] * 1e3, grid[-1] * 1e3, intervals), "",
        "| measure | mean | 95 % CI half-width | 95 % CI | relative half-width | se | n |", "|---|---|---|---|---|---|---|"]
    for key, label, unit, vals, mean, se, half, m in stats:
        s, u = scale[unit]
        rel = abs(half / mean) if m > 1 and mean != 0 else float("nan")
        lines.append("| %s [%s] | %s | %s | %s to %s | %s | %s | %d |" % (
            label, u, _fmt(mean * s), _fmt(half * s, ".2g"), _fmt((mean - half) * s), _fmt((mean + half) * s),
            "-" if not np.isfinite(rel) else "%.1f %%" % (100 * rel), _fmt(se * s, ".2g"), m))
    lines += ["", "Per seed (F<i>: mean load over stroke interval i; F all: over the common stroke):", "",
              "| seed | " + " | ".join("%s [%s]" % (SHORT.get(k, k.replace("mean_load_", "F").replace("_N", "")),
                                                  scale[u][1]) for k, _, u, *_ in stats) + " |",
              "|---|" + "---|" * len(stats)]
    for j, sd in enumerate(seeds):
        lines.append("| %d | " % sd + " | ".join(_fmt(st[3][j] * scale[st[2]][0]) for st in stats) + " |")
    lines += ["", "Files: `ensemble.csv` (mean curve), `ensemble_stats.csv`, `ensemble.png`, `seed-<k>/` (runs; "
              "`seed-<k>/scene.toml`: the scene each ran, with its overrides).", ""]
    text = "\n".join(lines)
    open(os.path.join(ens, "ensemble.md"), "w").write(text)
    print(text)
    figure(ens, runs, cs, scene, stage)
    return 0


def figure(ens, runs, cs, scene, stage):
    fig, ax = plt.subplots(figsize=(7, 4.8))
    for i, r in enumerate(runs):
        ax.plot(r["disp"] * 1e3, r["load"], lw=0.6, alpha=0.55, color="C%d" % (i % 10),
                label="seed %d" % r["seed"] if len(runs) <= 10 else None)
    g = cs["grid"] * 1e3
    if cs["n"] > 1:
        ax.fill_between(g, cs["low"], cs["high"], color="k", alpha=0.25, lw=0, label="95 % CI of the mean")
    ax.plot(g, cs["mean"], color="k", lw=2.2, label="mean of %d seeds" % cs["n"])
    ax.set_xlabel("footing displacement [mm]")
    ax.set_ylabel("footing load [N]")
    ax.set_title("%s (%s): n = %d seeds, mean and 95 %% band" % (scene, stage, cs["n"]))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(ens, "ensemble.png"), dpi=120)
    plt.close(fig)


def parse_seeds(spec):
    """N -> 1..N; A-B -> A..B; a comma list of seeds and A-B ranges -> those (sorted, unique)."""
    spec = spec.strip()
    if re.fullmatch(r"\d+", spec):
        n = int(spec)
        if n < 1:
            raise ValueError("--seeds %s: N must be at least 1" % spec)
        return list(range(1, n + 1))
    seeds = set()
    for part in spec.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m or (m.group(2) and int(m.group(2)) < int(m.group(1))):
            raise ValueError("--seeds %s: expected N, A-B or a comma list of seeds and ranges (A <= B)" % spec)
        seeds.update(range(int(m.group(1)), int(m.group(2) or m.group(1)) + 1))
    return sorted(seeds)


def seed_sets(scene, seed, sets=(), stage_sets=()):
    """The overrides of seed `seed`'s run of the scene file: the "table.key=value" ones, the
    "stage.key=value" ones as "stage.STAGE.key=value", run.seed = seed, and
    output.traffic_log=false unless the scene or an override says traffic_log. A malformed one
    raises KeyError (the coordinator checks the rest)."""
    out = []
    for e in sets:
        k, eq, v = e.partition("=")
        if not eq or "." not in k:
            raise KeyError("--set %s: expected table.key=value" % e)
        out.append("%s=%s" % (k.strip(), v.strip()))
    for e in stage_sets:
        k, eq, v = e.partition("=")
        stage, dot, key = k.strip().partition(".")
        if not eq or not dot or not stage or not key:
            raise KeyError("--stage-set %s: expected stage.key=value" % e)
        out.append(overrides.stage_set(stage, key.strip(), v.strip()))
    return overrides.quiet_traffic(scene, out + ["run.seed=%d" % seed])


def tail(path, n=15):
    try:
        return open(path, errors="replace").read().rstrip("\n").split("\n")[-n:]
    except OSError:
        return []


def run(ens, scene, seeds, jobs=1, sets=(), stage_sets=(), launcher=None, check_only=False, coordinator=None):
    """Runs the seeds (see the module doc); returns the exit code (0, 2 bad scene, 3 a run failed,
    130 interrupted). check_only: check every seed's overrides and the finished seeds, run nothing.
    coordinator: the command that reads scenes (default: the build's coordinator)."""
    launcher = launcher or os.path.join(ROOT, "launch", "run")
    try:
        seed_runs = {k: seed_sets(scene, k, sets, stage_sets) for k in seeds}
    except KeyError as ex:
        print("ensemble: %s" % ex.args[0], file=sys.stderr)
        return 2
    pending, done_before = [], []
    for k in seeds:
        d = os.path.join(ens, "seed-%d" % k)
        if os.path.isdir(d) and run_finished(d):
            try:
                same = overrides.ran(d, scene, seed_runs[k], coordinator)
            except ValueError as ex:
                print("ensemble: seed %d: the scene with its overrides is refused: %s" % (k, ex), file=sys.stderr)
                return 2
            if not same:
                print("ensemble: %s was run from a different scene or other values than seed %d's (%s); use a new "
                      "ensemble folder" % (d, k, " ".join(overrides.set_args(seed_runs[k]))), file=sys.stderr)
                return 2
            done_before.append(k)
        else:
            pending.append(k)
    for k in pending:  # check every seed's run before anything starts
        r = subprocess.run([launcher, scene, "--check", "--no-build"] + overrides.set_args(seed_runs[k]),
                           capture_output=True, text=True)
        if r.returncode != 0:
            print("ensemble: seed %d: the scene with its overrides is refused (exit %d): %s" %
                  (k, r.returncode, (r.stderr or r.stdout).strip()), file=sys.stderr)
            return 2
    if check_only:
        print("ensemble: %d seed(s) checked, %d of them finished before in %s" % (len(seeds), len(done_before), ens),
              file=sys.stderr)
        return 0
    os.makedirs(ens, exist_ok=True)
    meta_path = os.path.join(ens, "ensemble.json")
    meta = json.load(open(meta_path)) if os.path.exists(meta_path) else {}
    meta.update(scene=os.path.abspath(scene), set=list(sets), stage_set=list(stage_sets),
                seeds=sorted(set(meta.get("seeds", [])) | set(seeds)))
    json.dump(meta, open(meta_path, "w"), indent=1)
    if done_before:
        print("ensemble: seeds %s already finished in %s (not run again)" % (",".join(map(str, done_before)), ens),
              file=sys.stderr)
    for k in pending:  # an unfinished folder from an earlier pass is kept, under another name
        d = os.path.join(ens, "seed-%d" % k)
        if os.path.exists(d):
            i = 1
            while os.path.exists("%s.incomplete-%d" % (d, i)):
                i += 1
            os.rename(d, "%s.incomplete-%d" % (d, i))
            print("ensemble: seed %d: unfinished folder of an earlier pass kept as %s.incomplete-%d; running it again"
                  % (k, d, i), file=sys.stderr)
    active, failed, finished, interrupted = {}, [], 0, []
    queue = list(pending)
    t_all = time.time()
    try:
        while queue or active:
            while queue and len(active) < max(1, jobs):
                k = queue.pop(0)
                log = open(os.path.join(ens, "seed-%d.log" % k), "w")
                p = subprocess.Popen([launcher, scene, "--no-build"] + overrides.set_args(seed_runs[k]) +
                                     ["--run-dir", os.path.join(ens, "seed-%d" % k)], stdout=log, stderr=subprocess.STDOUT)
                active[p.pid] = (k, p, log, time.time())
            pid, status = os.wait()
            if pid not in active:
                continue
            k, p, log, t0 = active.pop(pid)
            p.returncode = os.waitstatus_to_exitcode(status)
            log.close()
            rc = p.returncode if p.returncode >= 0 else 128 - p.returncode
            d = os.path.join(ens, "seed-%d" % k)
            if rc == 0 and not run_finished(d):
                rc = -1
            finished += 1
            if rc == 130:  # the run was interrupted (Ctrl-C reaches every process): start no other
                interrupted.append(k)
                queue.clear()
                print("ensemble: seed %d interrupted; starting no other run" % k, file=sys.stderr, flush=True)
            elif rc == 0:
                print("ensemble: [%d/%d] seed %d done in %.0f s" % (finished, len(pending), k, time.time() - t0),
                      file=sys.stderr, flush=True)
            else:
                failed.append((k, rc))
                lines = tail(os.path.join(ens, "seed-%d.log" % k))
                print("ensemble: [%d/%d] seed %d FAILED (%s) after %.0f s; last lines of %s:\n    %s" % (
                    finished, len(pending), k, "exit code %d" % rc if rc >= 0 else "exit 0 but no finished run",
                    time.time() - t0, os.path.join(ens, "seed-%d.log" % k), "\n    ".join(lines)),
                    file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print("ensemble: interrupted; stopping %d run(s); run the same command again to resume" % len(active),
              file=sys.stderr)
        branching.stop_runs(list(active.values()))
        return 130
    if interrupted:
        print("ensemble: interrupted (seeds %s); run the same command again to resume" %
              ",".join(map(str, interrupted)), file=sys.stderr)
        return 130
    print("ensemble: %d run(s) in %.0f s, %d failed; %d seed(s) finished in %s" % (
        len(pending), time.time() - t_all, len(failed), len(seeds) - len(failed), ens), file=sys.stderr)
    if failed:
        print("ensemble: FAILED seeds: %s" % ", ".join("seed-%d (%s)" % (k, "exit code %d" % rc if rc >= 0 else
                                                                         "no finished run") for k, rc in failed),
              file=sys.stderr)
        return 3
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a scene over seeds")
    r.add_argument("ensemble")
    r.add_argument("--scene", required=True)
    r.add_argument("--seeds", required=True, help="N (1..N), A-B, or a comma list")
    r.add_argument("--jobs", type=int, default=1, help="runs at once (default 1)")
    r.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE")
    r.add_argument("--stage-set", action="append", default=[], metavar="STAGE.KEY=VALUE")
    r.add_argument("--check", action="store_true", help="check every seed's run, run nothing")
    r.add_argument("--launcher", help=argparse.SUPPRESS)  # tests: a stand-in for launch/run
    t = sub.add_parser("table", help="tables and figure of an ensemble folder")
    t.add_argument("ensemble")
    t.add_argument("--stage", default="penetrate")
    t.add_argument("--intervals", type=int, default=4)
    a = ap.parse_args(argv)
    if a.command == "run":
        try:
            seeds = parse_seeds(a.seeds)
        except ValueError as ex:
            print("ensemble: %s" % ex, file=sys.stderr)
            return 2
        if not os.path.isfile(a.scene):
            print("ensemble: cannot read scene %s" % a.scene, file=sys.stderr)
            return 2
        if a.jobs < 1:
            print("ensemble: --jobs must be at least 1", file=sys.stderr)
            return 2
        def stop(signum, frame):
            raise KeyboardInterrupt
        signal.signal(signal.SIGTERM, stop)  # SIGTERM stops the runs as Ctrl-C does
        try:
            return run(a.ensemble, a.scene, seeds, a.jobs, a.set, a.stage_set, a.launcher, a.check)
        except KeyboardInterrupt:  # before any run started
            print("ensemble: interrupted", file=sys.stderr)
            return 130
    if a.intervals < 1:
        print("ensemble: --intervals must be at least 1", file=sys.stderr)
        return 2
    if not os.path.isdir(a.ensemble):
        print("ensemble: no folder %s" % a.ensemble, file=sys.stderr)
        return 2
    return table(a.ensemble, a.stage, a.intervals)


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""Compare the footing load-displacement curves of two or more runs (e.g. the same scene with
fdm_node and with fem_node as the continuum).

usage: compare_curves.py RUN_DIR [RUN_DIR ...] [--stage NAME] [--markdown]

For each run folder: the curve of its penetration stage (history_<i>_<stage>.csv, columns
dem.footing_disp_m and dem.footing_fz_N), and the stage table of summary.txt.
Reported per run: peak load and the displacement at it; initial stiffness = least-squares
slope of F against d through the points before the peak with F <= 0.5 F_peak; per-stage wall
time and each node's compute seconds. Against the first run (the reference): the normalised
curve difference = RMS over the common displacement range of (F_run(d) - F_ref(d)), with both
curves linearly interpolated on 200 equally spaced displacements, divided by the reference
peak load; and the ratios of peak load and initial stiffness.
Exit codes: 0 ok, 2 a run folder lacks its curve or summary.
"""
import argparse
import csv
import math
import re
import sys
from pathlib import Path

import numpy as np


def fail(msg):
    print(f"compare_curves: {msg}", file=sys.stderr)
    sys.exit(2)


def read_curve(run: Path, stage: str):
    files = sorted(run.glob(f"history_*_{stage}.csv"))
    if not files:
        fail(f"{run}: no history_*_{stage}.csv (stage '{stage}' not run?)")
    d, f = [], []
    with open(files[0], newline="") as fh:
        for row in csv.DictReader(fh):
            try:
                d.append(float(row["dem.footing_disp_m"]))
                f.append(float(row["dem.footing_fz_N"]))
            except (KeyError, ValueError):
                fail(f"{files[0]}: needs numeric columns dem.footing_disp_m and dem.footing_fz_N")
    if len(d) < 3:
        fail(f"{files[0]}: fewer than 3 rows")
    return np.array(d), np.array(f)


STAGE = re.compile(r"^  (\S+) \[(\S+)\]: steps (\d+)\.\.(\d+) \((\d+)\), wall ([0-9.]+) s")
NODE = re.compile(r"^    (\S+): compute ([0-9.]+) s, bus wait ([0-9.]+) s")


def read_summary(run: Path):
    path = run / "summary.txt"
    if not path.exists():
        fail(f"{run}: no summary.txt")
    stages, current, continuum = [], None, ""
    for line in path.read_text().splitlines():
        m = STAGE.match(line)
        if m:
            current = {"name": m[1], "action": m[2], "steps": int(m[5]), "wall_s": float(m[6]), "compute": {}}
            stages.append(current)
            continue
        m = NODE.match(line)
        if m and current is not None:
            current["compute"][m[1]] = float(m[2])
        m = re.match(r"^  continuum: (\S+) pid ", line)
        if m:
            continuum = m[1]
    return continuum, stages


def metrics(d, f):
    i_peak = int(np.argmax(f))
    peak = float(f[i_peak])
    pre = np.arange(i_peak + 1)
    sel = pre[f[pre] <= 0.5 * peak]
    k0 = float(np.dot(d[sel], f[sel]) / np.dot(d[sel], d[sel])) if len(sel) >= 2 and np.any(d[sel] != 0) else math.nan
    return {"peak_N": peak, "d_peak_m": float(d[i_peak]), "k0_N_per_m": k0, "d_max_m": float(d.max())}


def curve_difference(ref, other, peak_ref):
    (d0, f0), (d1, f1) = ref, other
    lo, hi = max(d0.min(), d1.min()), min(d0.max(), d1.max())
    if not hi > lo:
        return math.nan, (lo, hi)
    grid = np.linspace(lo, hi, 200)
    # interp needs increasing x: sort by displacement (the footing only moves down here).
    a = np.interp(grid, *zip(*sorted(zip(d0, f0))))
    b = np.interp(grid, *zip(*sorted(zip(d1, f1))))
    return float(np.sqrt(np.mean((b - a) ** 2)) / peak_ref), (lo, hi)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--stage", default="penetrate", help="stage whose curve is compared (default penetrate)")
    ap.add_argument("--markdown", action="store_true", help="print markdown tables")
    a = ap.parse_args()
    runs = []
    for r in a.runs:
        d, f = read_curve(r, a.stage)
        solver, stages = read_summary(r)
        runs.append({"dir": r, "solver": solver or r.name, "curve": (d, f), "m": metrics(d, f), "stages": stages})
    ref = runs[0]
    md = a.markdown
    hdr = ["run", "continuum", "peak load [N]", "d at peak [mm]", "initial stiffness [N/mm]", "peak / ref",
           "stiffness / ref", "curve difference / ref peak"]
    rows = []
    for r in runs:
        m = r["m"]
        diff, _ = curve_difference(ref["curve"], r["curve"], ref["m"]["peak_N"])
        rows.append([r["dir"].name, r["solver"], f"{m['peak_N']:.4g}", f"{m['d_peak_m'] * 1e3:.4g}",
                     f"{m['k0_N_per_m'] * 1e-3:.4g}", f"{m['peak_N'] / ref['m']['peak_N']:.4f}",
                     f"{m['k0_N_per_m'] / ref['m']['k0_N_per_m']:.4f}", f"{diff:.4f}"])
    table(hdr, rows, md)
    print()
    names = []
    for r in runs:
        for s in r["stages"]:
            if s["name"] not in names:
                names.append(s["name"])
    hdr = ["stage"] + [f"{r['solver']} wall [s] (continuum / dem compute)" for r in runs]
    rows = []
    for n in names + ["total"]:
        row = [n]
        for r in runs:
            st = r["stages"] if n == "total" else [s for s in r["stages"] if s["name"] == n]
            if not st:
                row.append("-")
                continue
            wall = sum(s["wall_s"] for s in st)
            cc = sum(s["compute"].get("continuum", 0.0) for s in st)
            dc = sum(s["compute"].get("dem", 0.0) for s in st)
            steps = sum(s["steps"] for s in st)
            row.append(f"{wall:.1f} ({cc:.1f} / {dc:.1f}), {steps} steps")
        rows.append(row)
    table(hdr, rows, md)
    return 0


def table(hdr, rows, md):
    if md:
        print("| " + " | ".join(hdr) + " |")
        print("|" + "---|" * len(hdr))
        for r in rows:
            print("| " + " | ".join(r) + " |")
        return
    w = [max(len(str(x)) for x in col) for col in zip(hdr, *rows)]
    for r in [hdr] + rows:
        print("  ".join(str(x).ljust(n) for x, n in zip(r, w)))


if __name__ == "__main__":
    sys.exit(main())

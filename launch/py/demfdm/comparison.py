"""Several runs side by side: their result values and how far their footing curves differ
(command line: `python3 -m demfdm RUN [RUN ...]`, demfdm/__main__.py).
"""
import math
import os
import sys

import numpy as np

from .run import Run

_LAUNCH_PY = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if _LAUNCH_PY not in sys.path:
    sys.path.append(_LAUNCH_PY)
import paper_figures  # noqa: E402  (elastic_branch: the k_e rule)

MEASURES = ("peak_N", "settlement_at_peak_m", "k_e_N_m", "final_N", "wall_s")


def elastic_stiffness(settlement, load, failures):
    """k_e [N/m]: least-squares slope of load on settlement over the elastic branch
    (launch/py/paper_figures.elastic_branch); NaN with fewer than 5 rows."""
    branch = paper_figures.elastic_branch(load, failures)
    if branch is None or branch[1] - branch[0] + 1 < 5:
        return float("nan")
    i0, ie = branch
    return float(np.polyfit(settlement[i0:ie + 1], load[i0:ie + 1], 1)[0])


def curve_values(run):
    """The result values recomputed from the run's footing curve (for runs whose summary.json has
    no "result"): peak_N, settlement_at_peak_m, final_N, final_settlement_m, k_e_N_m."""
    stage = run.penetration_stage()
    if stage is None:
        return {}
    h = run.history(stage)
    s, f = h["settlement"], h["load"]
    if not len(f):
        return {}
    ip = int(np.argmax(f))
    k_e = elastic_stiffness(s, f, h["dem.bond_failures"]) if "dem.bond_failures" in h else float("nan")
    return {"stage": stage, "peak_N": float(f[ip]), "settlement_at_peak_m": float(s[ip]), "final_N": float(f[-1]),
            "final_settlement_m": float(s[-1]), "k_e_N_m": k_e}


def _value(run, key, computed):
    if callable(key):
        return key(run)
    if key == "wall_s":
        return run.wall_s
    res = run.result or {}
    if key in res:
        return res[key]
    if key in computed:
        return computed[key]
    return float("nan")


def _sorted_curve(run):
    s, f = run.curve()
    order = np.argsort(s, kind="stable")
    return np.asarray(s, float)[order], np.asarray(f, float)[order]


def compare(runs, measure=MEASURES, points=200, labels=None):
    """A table (list of dicts, one per run, the first run is the reference) of:
      run, path              a label (labels[i], else the folder name) and the folder
      <measure>              each measure: a key of summary.json's "result" (peak_N,
                             settlement_at_peak_m, k_e_N_m, final_N, final_settlement_m,
                             bonds_broken_shear, ...), "wall_s" (the run's wall time), or a pair
                             (name, function(Run) -> value); result keys the summary lacks are
                             recomputed from the curve (curve_values), else NaN
      curve_max_diff, curve_rms_diff
                             the largest and the root-mean-square |load - reference load| on a
                             common settlement grid, over the first run's peak load [-]
      grid_from_m, grid_to_m the grid: `points` settlements over the range both curves reach
    `runs` are Run objects or folders. Curves are sorted by settlement and interpolated linearly.
    A run without a footing curve gets NaN differences."""
    runs = [r if isinstance(r, Run) else Run(r) for r in runs]
    if not runs:
        return []
    keys = [(m if isinstance(m, str) else m[0], m if isinstance(m, str) else m[1]) for m in measure]
    curves = []
    for r in runs:
        try:
            curves.append(_sorted_curve(r))
        except (KeyError, OSError, ValueError):
            curves.append(None)
    ref = curves[0]
    ref_peak = float(np.max(ref[1])) if ref is not None and len(ref[1]) else float("nan")
    rows = []
    for i, (r, c) in enumerate(zip(runs, curves)):
        missing = [k for _, k in keys if isinstance(k, str) and k != "wall_s" and k not in (r.result or {})]
        computed = curve_values(r) if missing else {}
        row = {"run": labels[i] if labels else r.name, "path": r.path}
        for name, k in keys:
            v = _value(r, k, computed)
            row[name] = float(v) if isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool) else v
        row.update(curve_difference(ref, c, ref_peak, points))
        rows.append(row)
    return rows


def curve_difference(ref, other, ref_peak, points=200):
    """{curve_max_diff, curve_rms_diff, grid_from_m, grid_to_m} of two (settlement, load) curves
    (settlement increasing): |other - ref| on `points` settlements over their common range, over
    ref_peak."""
    nan = float("nan")
    if ref is None or other is None or not len(ref[0]) or not len(other[0]):
        return {"curve_max_diff": nan, "curve_rms_diff": nan, "grid_from_m": nan, "grid_to_m": nan}
    lo, hi = max(ref[0][0], other[0][0]), min(ref[0][-1], other[0][-1])
    if not hi > lo:
        return {"curve_max_diff": nan, "curve_rms_diff": nan, "grid_from_m": float(lo), "grid_to_m": float(hi)}
    grid = np.linspace(lo, hi, points)
    d = np.interp(grid, *other) - np.interp(grid, *ref)
    return {"curve_max_diff": float(np.max(np.abs(d)) / ref_peak), "curve_rms_diff": float(np.sqrt(np.mean(d * d)) / ref_peak),
            "grid_from_m": float(lo), "grid_to_m": float(hi)}


def format_table(rows, markdown=False, columns=None):
    """The rows of compare() as text (aligned columns, or a markdown table)."""
    if not rows:
        return ""
    columns = columns or [c for c in rows[0] if c != "path"]

    def fmt(v):
        if isinstance(v, float):
            return "nan" if math.isnan(v) else "%.4g" % v
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    if markdown:
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        lines += ["| " + " | ".join(c) + " |" for c in cells]
        return "\n".join(lines)
    width = [max(len(h), *(len(c[j]) for c in cells)) for j, h in enumerate(columns)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(columns, width))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(c, width)) for c in cells]
    return "\n".join(lines)

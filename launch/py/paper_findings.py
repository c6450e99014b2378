#!/usr/bin/python3
"""The paper's findings with confidence intervals, from seed ensembles of its scenes
(launch/study paper --seeds N; docs/paper-study.md, docs/convergence.md).

Usage:
  /usr/bin/python3 launch/py/paper_findings.py STUDY_DIR

STUDY_DIR holds one ensemble folder per scene, named after scenes/paper_<name>.toml (100g_sbm,
100g_pbm, 1g_sbm, 50g_sbm, 200g_sbm), each with seed-<k>/ run folders (launch/py/ensemble.py).
Writes STUDY_DIR/findings.md, findings.csv and findings.png (seed-mean curves with 95 % bands,
quarter-stroke means with 95 % intervals):

- per scene: seed mean ± 95 % CI of the raw peak, of the mean load over each quarter of the common
  stroke and over the whole stroke, and of k_e (elastic stiffness before the first bond failure);
- "initial response independent of g" and "bearing capacity dependent on g": each g-level against
  100 g. The g-level sets the servo stress, so each g has its own specimens: the difference of the
  means is unpaired, with a 95 % interval from the two standard errors and the t quantile of the
  smaller sample (conservative); and, since seed k generates the same REV at every g (the g-level
  acts from the servo on), also paired over the seeds both scenes have;
- "SBM more hardening than PBM": one seed gives one packing for both models (docs/paper-study.md),
  so the difference is paired over the seeds both have.
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ensemble  # noqa: E402

SCENES = ["1g_sbm", "50g_sbm", "100g_sbm", "200g_sbm", "100g_pbm"]
G = {"1g_sbm": 1, "50g_sbm": 50, "100g_sbm": 100, "200g_sbm": 200}
INTERVALS = 4


def metrics(runs, edges):
    """{seed: {measure: value}}: peak, q1..q4, all (mean loads), k_e."""
    out = {}
    for r in runs:
        d, f = r["disp"], r["load"]
        m = {"peak": float(np.max(f)), "all": ensemble.interval_means(d, f, [edges[0], edges[-1]])[0], "k_e": r["k_e"]}
        for i, v in enumerate(ensemble.interval_means(d, f, edges)):
            m["q%d" % (i + 1)] = v
        out[r["seed"]] = m
    return out


def unpaired(a, b):
    """(mean difference a - b, half-width of its 95 % interval, n_a, n_b)."""
    ma, sa, _, na = ensemble.scalar_stats(a)
    mb, sb, _, nb = ensemble.scalar_stats(b)
    if na < 2 or nb < 2:
        return ma - mb, float("nan"), na, nb
    return ma - mb, ensemble.t975(min(na, nb) - 1) * math.sqrt(sa * sa + sb * sb), na, nb


def cell(vals):
    m, _, h, n = ensemble.scalar_stats(vals)
    return "n/a" if n == 0 else ("%.4g ± %.2g" % (m, h) if n > 1 else "%.4g" % m)


MEASURES = [("peak", "raw peak [N]"), ("q1", "mean load q1 [N]"), ("q2", "q2 [N]"), ("q3", "q3 [N]"),
            ("q4", "q4 [N]"), ("all", "mean load, stroke [N]"), ("k_e", "k_e [N/m]")]


def figure(study, runs, met, edges):
    """findings.png: (left) each scene's seed-mean load against settlement / D_f with its 95 % band,
    the curves smoothed by a moving mean over 1/40 of the common stroke (the raw signal is a
    sequence of spikes); (right) the mean load over each quarter of the stroke, seed mean and 95 %
    interval per scene."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = [n for n in SCENES if n in runs]
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.6))
    lo, hi = edges[0], edges[-1]
    grid = np.linspace(lo, hi, 400)
    w = max(1, len(grid) // 40)
    kern = np.ones(w) / w
    d_f = hi / 0.2  # the paper scenes stop at 0.2 D_f (stage key depth_ratio), the common stroke's end
    for i, n in enumerate(names):
        smooth = [np.convolve(np.interp(grid, r["disp"], r["load"]), kern, mode="same") for r in runs[n]]
        cs = ensemble.curve_stats([(grid, y) for y in smooth], grid)
        x = grid / d_f
        a.plot(x, cs["mean"], color="C%d" % i, lw=1.8, label="%s (n = %d)" % (n, cs["n"]))
        if cs["n"] > 1:
            a.fill_between(x, cs["low"], cs["high"], color="C%d" % i, alpha=0.18, lw=0)
        q = [[m["q%d" % (k + 1)] for m in met[n].values()] for k in range(INTERVALS)]
        means = [ensemble.scalar_stats(v)[0] for v in q]
        halves = [ensemble.scalar_stats(v)[2] for v in q]
        xs = np.arange(INTERVALS) + (i - (len(names) - 1) / 2) * 0.8 / max(1, len(names))
        b.errorbar(xs, means, yerr=np.nan_to_num(halves), fmt="o", color="C%d" % i, capsize=3, label=n)
    a.set_xlabel("settlement / footing diameter s / D_f [-]")
    a.set_ylabel("footing load [N] (moving mean over 1/40 of the stroke)")
    a.set_title("seed mean and 95 % band")
    a.grid(True, alpha=0.3)
    a.legend(fontsize=8)
    b.set_xticks(range(INTERVALS))
    b.set_xticklabels(["quarter %d" % (k + 1) for k in range(INTERVALS)])
    b.set_ylabel("mean load over the quarter of the stroke [N]")
    b.set_title("seed mean and 95 % interval")
    b.grid(True, alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(study, "findings.png"), dpi=120)
    plt.close(fig)


def findings(study):
    runs = {n: ensemble.load_runs(os.path.join(study, n)) for n in SCENES if os.path.isdir(os.path.join(study, n))}
    runs = {n: r for n, r in runs.items() if r}
    if not runs:
        raise SystemExit("paper findings: no finished ensemble runs in %s" % study)
    lo = max(float(r["disp"][0]) for rs in runs.values() for r in rs)
    hi = min(float(r["disp"][-1]) for rs in runs.values() for r in rs)
    edges = list(np.linspace(lo, hi, INTERVALS + 1))
    met = {n: metrics(rs, edges) for n, rs in runs.items()}
    md = ["# The paper's findings with confidence intervals", "",
          "Study folder `%s`. Seed mean ± half-width of the 95 %% confidence interval (Student t). Loads are "
          "means over the common stroke %.4g to %.4g mm and its %d quarters." % (study, lo * 1e3, hi * 1e3, INTERVALS),
          "", "## Every scene", "", "| scene | n | " + " | ".join(l for _, l in MEASURES) + " |",
          "|---|---|" + "---|" * len(MEASURES)]
    csv = ["scene,seed,measure,value"]
    for n in SCENES:
        if n not in met:
            continue
        md.append("| %s | %d | " % (n, len(met[n])) + " | ".join(cell([m[k] for m in met[n].values()])
                                                            for k, _ in MEASURES) + " |")
        for s, m in sorted(met[n].items()):
            csv += ["%s,%s,%s,%r" % (n, s, k, v) for k, v in sorted(m.items())]
    md += ["", "## Initial response and bearing capacity against g (each g against 100 g, unpaired)", "",
           "| g | " + " | ".join(l for _, l in MEASURES) + " |", "|---|" + "---|" * len(MEASURES)]
    ref = met.get("100g_sbm")
    for n in ["1g_sbm", "50g_sbm", "200g_sbm"]:
        if ref and n in met:
            row = []
            for k, _ in MEASURES:
                a, b = [m[k] for m in met[n].values()], [m[k] for m in ref.values()]
                d, h, _, _ = unpaired(a, b)
                row.append(ensemble.verdict(d, h, ensemble.scalar_stats(b)[0]))
            md.append("| %d | " % G[n] + " | ".join(row) + " |")
    md += ["", "## The same, paired by seed", "",
           "Seed k generates the same REV at every g-level (the g-level acts from the servo on), so the seed's "
           "packing is shared and the difference can be paired over the seeds both scenes have; the unpaired "
           "table above does not use that and is conservative.", "",
           "| g | " + " | ".join(l for _, l in MEASURES) + " |", "|---|" + "---|" * len(MEASURES)]
    for n in ["1g_sbm", "50g_sbm", "200g_sbm"]:
        if ref and n in met:
            row = []
            for k, _ in MEASURES:
                a = {s: m[k] for s, m in met[n].items()}
                b = {s: m[k] for s, m in ref.items()}
                row.append(ensemble.paired_verdict(a, b))
            md.append("| %d | " % G[n] + " | ".join(row) + " |")
    md += ["", "## SBM against PBM at 100 g (paired: one packing per seed)", "",
           "| " + " | ".join(l for _, l in MEASURES) + " |", "|" + "---|" * len(MEASURES)]
    if "100g_sbm" in met and "100g_pbm" in met:
        row = []
        for k, _ in MEASURES:
            a = {s: m[k] for s, m in met["100g_sbm"].items()}
            b = {s: m[k] for s, m in met["100g_pbm"].items()}
            row.append(ensemble.paired_verdict(a, b))
        md.append("| " + " | ".join(row) + " |")
    figure(study, runs, met, edges)
    md += ["", "![findings](findings.png)"]
    text = "\n".join(md) + "\n"
    open(os.path.join(study, "findings.md"), "w").write(text)
    open(os.path.join(study, "findings.csv"), "w").write("\n".join(csv) + "\n")
    return text


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    print(findings(sys.argv[1]))

"""The standard figures of a run folder, and the curves of several runs in one figure.

  PYTHONPATH=launch/py /usr/bin/python3 -m demfdm.plot RUN [--out DIR]
  PYTHONPATH=launch/py /usr/bin/python3 -m demfdm.plot RUN_A RUN_B [...] --out DIR

One run: writes into DIR (default: the run folder, as launch/run does) what the run has:
  load_settlement.png   footing load against settlement at model scale, and normalised:
                        q / sigma_c against s / D_f (q = F / (pi D_f^2 / 4))
  stress_profiles.png   vertical stress against depth after the equilibrium stages
(the figures of launch/py/run_figures.py, which launch/run draws after every run).
Several runs: each run's figures into DIR/<run folder name>/, and into DIR
  compare_load_settlement.png   every run's curve, raw and normalised, in one figure
  compare.md                    demfdm.compare's table (result values, curve differences)
Prints the paths written; exit 0 (also when a run has nothing to draw), 1 on an unreadable run.
"""
import argparse
import copy
import math
import os
import sys

from .comparison import compare, format_table
from .run import DEFAULT_BALL_BALL_MODEL, Run

_LAUNCH_PY = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run_figures():
    """launch/py/run_figures.py (the standard figures; it selects the Agg backend), imported when
    first drawing, so that argument errors come back without loading matplotlib."""
    if _LAUNCH_PY not in sys.path:
        sys.path.append(_LAUNCH_PY)
    import run_figures

    return run_figures


def scene_with_defaults(scene):
    """A copy of the scene with the ball-ball contact model filled in when the scene leaves it to
    its default (softbond): run_figures.bond_strength reads a missing model as linear and would
    draw q instead of q / sigma_c."""
    if "dem" not in scene or "model" in scene["dem"].get("ball_ball", {}):
        return scene
    scene = copy.deepcopy(scene)
    scene["dem"].setdefault("ball_ball", {})["model"] = DEFAULT_BALL_BALL_MODEL
    return scene


def figures(run, out=None):
    """Draws the standard figures of one run (a Run or a folder) into out (default: the run
    folder); returns the paths written (none for a run without a footing or profiles)."""
    run = run if isinstance(run, Run) else Run(run)
    out = out or run.path
    os.makedirs(out, exist_ok=True)
    scene = scene_with_defaults(run.scene)
    rf = _run_figures()
    made = [rf.load_settlement(run.path, scene, out), rf.stress_profiles(run.path, scene, out)]
    return [p for p in made if p]


def curves_figure(runs, path, labels=None):
    """Every run's footing curve in one figure: load [N] against settlement [mm], and q / sigma_c
    against s / D_f (q [MPa] when a scene has no bond strength). Returns path, or None when no
    run has a curve."""
    _run_figures()
    import matplotlib.pyplot as plt

    runs = [r if isinstance(r, Run) else Run(r) for r in runs]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    drawn = 0
    norm_label = None
    for i, r in enumerate(runs):
        try:
            s, f = r.curve()
        except (KeyError, OSError, ValueError):
            continue
        label = labels[i] if labels else r.name
        axes[0].plot(s * 1e3, f, lw=1.1, label=label)
        d_f = r.footing_diameter
        sigma = r.bond_strength
        if math.isfinite(d_f) and d_f > 0:
            q = f / (math.pi * d_f ** 2 / 4)
            if sigma:
                axes[1].plot(s / d_f, q / sigma, lw=1.1, label=label)
                norm_label = norm_label or "bearing pressure over bond strength, q / sigma_c [-]"
            else:
                axes[1].plot(s / d_f, q * 1e-6, lw=1.1, label=label + " (q in MPa)")
                norm_label = norm_label or "bearing pressure q [MPa]"
        drawn += 1
    if not drawn:
        plt.close(fig)
        return None
    axes[0].set_xlabel("settlement at model scale [mm]")
    axes[0].set_ylabel("footing load at model scale [N]")
    axes[0].set_title("Load-settlement of %d runs" % drawn, fontsize=10)
    axes[1].set_xlabel("settlement over footing diameter, s / D_f [-]")
    axes[1].set_ylabel(norm_label or "no footing diameter in the scenes")
    axes[1].set_title("Normalised", fontsize=10)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python3 -m demfdm.plot",
                                 description="The standard figures of a run folder (load-settlement, "
                                             "normalised; stress-depth profiles).")
    ap.add_argument("runs", nargs="+", metavar="RUN")
    ap.add_argument("--out", help="folder for the figures (default: the run folder; required for several runs)")
    a = ap.parse_args(argv)
    if len(a.runs) > 1 and not a.out:
        ap.error("several runs need --out DIR")
    try:
        runs = [Run(r) for r in a.runs]
        for r in runs:
            r.scene  # noqa: B018  (fails early on a folder without a readable scene.toml)
    except Exception as e:  # noqa: BLE001  (OSError, TOMLDecodeError: one line, exit 1)
        print("demfdm.plot: %s" % e, file=sys.stderr)
        return 1
    made = []
    if len(runs) == 1:
        made += figures(runs[0], a.out)
    else:
        used = set()
        for r in runs:
            name, k = r.name, 2
            while name in used:
                name, k = "%s-%d" % (r.name, k), k + 1
            used.add(name)
            made += figures(r, os.path.join(a.out, name))
        p = curves_figure(runs, os.path.join(a.out, "compare_load_settlement.png"))
        if p:
            made.append(p)
        md = os.path.join(a.out, "compare.md")
        with open(md, "w") as f:
            f.write("# Runs compared (first run = reference)\n\n")
            f.write(format_table(compare(runs), markdown=True) + "\n\n")
            f.write("curve_max_diff, curve_rms_diff: largest and RMS |load - reference load| on a common settlement "
                    "grid, over the reference's peak load.\n\n")
            for r in runs:
                f.write("- %s: %s\n" % (r.name, r.path))
        made.append(md)
    for p in made:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())

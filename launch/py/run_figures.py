#!/usr/bin/python3
"""The standard figures of one run folder (issue 14 item 2), made by launch/run after every run.

  /usr/bin/python3 launch/py/run_figures.py RUN_DIR

Writes into RUN_DIR, for what the run has:
  load_settlement.png   footing load against settlement at model scale, and normalised: bearing
                        pressure q = F / (pi D_f^2 / 4) over the bond strength sigma_c against
                        s / D_f (both scales share it); the peak and the elastic branch marked
  stress_profiles.png   vertical stress against depth after each equilibrium stage: DEM slabs,
                        FDM zone layers and the self-weight line rho_b N g depth
Axis labels are words with units. Prints the names of the figures written; exit 0 also when the
run has nothing to draw (a UCS or chain run), 1 on an unreadable run folder.
"""
import glob
import math
import os
import re
import sys
import tomllib

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import paper_figures  # noqa: E402  (elastic_branch: the k_e rule)


def read_csv(path):
    with open(path) as f:
        names = f.readline().strip().split(",")
        rows = [line.strip().split(",") for line in f if line.strip()]
    cols = {}
    for i, n in enumerate(names):
        try:
            cols[n] = np.array([float(r[i]) for r in rows])
        except (ValueError, IndexError):
            cols[n] = np.array([r[i] if i < len(r) else "" for r in rows])
    return cols


def scene_of(run):
    with open(os.path.join(run, "scene.toml"), "rb") as f:
        return tomllib.load(f)


def penetration_history(run):
    """(stage name, columns) of the last penetration stage history, or None."""
    best = None
    for p in glob.glob(os.path.join(run, "history_*_*.csv")):
        m = re.match(r"history_(\d+)_(.+)\.csv$", os.path.basename(p))
        if not m:
            continue
        cols = read_csv(p)
        if "dem.footing_disp_m" in cols and "dem.footing_fz_N" in cols and len(cols["dem.footing_fz_N"]) > 1:
            if best is None or int(m.group(1)) > best[0]:
                best = (int(m.group(1)), m.group(2), cols)
    return None if best is None else best[1:]


def bond_strength(scene):
    """The ball-ball bond's tensile strength [Pa] and its key, or (None, None)."""
    bb = scene.get("dem", {}).get("ball_ball", {})
    model = bb.get("model", "softbond")  # the scene schema's default (docs/scene-reference.md)
    if model == "softbond":
        return float(bb.get("softbond", {}).get("ten", 4.5e5)), "dem.ball_ball.softbond.ten"
    pb_ten = bb.get("pbond", {}).get("ten", 4.5e5)
    if model == "pbond" and pb_ten != "unbreakable":
        return float(pb_ten), "dem.ball_ball.pbond.ten"
    return None, None


def elastic_branch(cols):
    """Indices (first, last) of the elastic branch (paper_figures.elastic_branch) when it has at
    least 5 rows, or None."""
    if "dem.bond_failures" not in cols:
        return None
    b = paper_figures.elastic_branch(cols["dem.footing_fz_N"], cols["dem.bond_failures"])
    return b if b and b[1] - b[0] + 1 >= 5 else None


def load_settlement(run, scene, out):
    found = penetration_history(run)
    if found is None:
        return None
    stage, cols = found
    d_f = float(scene.get("dem", {}).get("footing", {}).get("diameter", float("nan")))
    s, f = cols["dem.footing_disp_m"], cols["dem.footing_fz_N"]
    g = scene.get("gravity", {}).get("level", 1)
    sigma, key = bond_strength(scene)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    ax = axes[0]
    ax.plot(s * 1e3, f, lw=1.2, color="C0", label="footing load")
    ip = int(np.argmax(f))
    ax.plot(s[ip] * 1e3, f[ip], "o", color="C3", label="peak %.4g N at %.4g mm" % (f[ip], s[ip] * 1e3))
    eb = elastic_branch(cols)
    if eb:
        i0, ie = eb
        k = np.polyfit(s[i0:ie + 1], f[i0:ie + 1], 1)
        xs = np.array([s[i0], s[ie]])
        ax.plot(xs * 1e3, np.polyval(k, xs), "k--", lw=1, label="elastic branch, k_e = %.3g N/m" % k[0])
    ax.set_xlabel("settlement at model scale [mm]")
    ax.set_ylabel("footing load at model scale [N]")
    ax.set_title("Load-settlement, %s g, D_f = %.3g mm (stage '%s')" % (g, d_f * 1e3, stage), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    if sigma and math.isfinite(d_f) and d_f > 0:
        q = f / (math.pi * d_f ** 2 / 4)
        ax.plot(s / d_f, q / sigma, lw=1.2, color="C0")
        ax.set_ylabel("bearing pressure over bond strength, q / sigma_c [-]")
        ax.set_title("Normalised, both scales: sigma_c = %.3g MPa (%s)" % (sigma * 1e-6, key.split(".")[-1]),
                     fontsize=10)
    else:
        q = f / (math.pi * d_f ** 2 / 4) if math.isfinite(d_f) and d_f > 0 else f
        ax.plot(s / d_f, q * 1e-6, lw=1.2, color="C0")
        ax.set_ylabel("bearing pressure q [MPa]")
        ax.set_title("Normalised settlement (no bond strength in the scene)")
    ax.set_xlabel("settlement over footing diameter, s / D_f [-]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = os.path.join(out, "load_settlement.png")
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def stress_profiles(run, scene, out):
    dem = sorted(glob.glob(os.path.join(run, "dem_profile_*.csv")))
    fdm = sorted(glob.glob(os.path.join(run, "fdm_profile_*.csv")))
    # The equilibrium stages (the gravity stage; not the penetration, whose profile is disturbed).
    stages = sorted({os.path.basename(p)[12:-4] for p in dem + fdm} - {"penetrate"})
    if not stages:
        return None
    fig, ax = plt.subplots(figsize=(5.6, 6.2))
    line_drawn = False
    for i, st in enumerate(stages):
        fp, dp = os.path.join(run, "fdm_profile_%s.csv" % st), os.path.join(run, "dem_profile_%s.csv" % st)
        if os.path.exists(fp):
            c = read_csv(fp)
            ax.plot(-c["szz_Pa"] * 1e-3, c["depth_m"] * 1e3, "s-", ms=4, color="C%d" % (2 * i),
                    label="continuum zones, after '%s'" % st)
            if not line_drawn and len(c["depth_m"]):
                d = np.linspace(0, c["depth_m"].max(), 50)
                slope = -c["selfweight_szz_Pa"][0] / c["depth_m"][0]
                ax.plot(slope * d * 1e-3, d * 1e3, "k--", lw=1, label="self-weight rho N g depth")
                line_drawn = True
        if os.path.exists(dp):
            c = read_csv(dp)
            ax.plot(-c["szz_Pa"] * 1e-3, c["depth_m"] * 1e3, "o-", ms=4, color="C%d" % (2 * i + 1),
                    label="DEM block slabs, after '%s'" % st)
            if not line_drawn and len(c["depth_m"]):
                d = np.linspace(0, c["depth_m"].max(), 50)
                ax.plot(-c["selfweight_szz_Pa"][0] / c["depth_m"][0] * d * 1e-3, d * 1e3, "k--", lw=1,
                        label="self-weight rho_b N g depth")
                line_drawn = True
    ax.invert_yaxis()
    ax.set_xlabel("vertical stress, compression positive [kPa]")
    ax.set_ylabel("depth below the top [mm]")
    ax.set_title("Stress-depth after equilibrium, %s g" % scene.get("gravity", {}).get("level", 1))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(out, "stress_profiles.png")
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    run = sys.argv[1]
    try:
        scene = scene_of(run)
    except (OSError, tomllib.TOMLDecodeError) as e:
        print("run_figures: %s: %s" % (run, e), file=sys.stderr)
        return 1
    made = [p for p in (load_settlement(run, scene, run), stress_profiles(run, scene, run)) if p]
    for p in made:
        print(os.path.basename(p))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""Figures 3-7 of the paper's coupled footing study (docs/paper-study.md) from run folders.

Usage:
  /usr/bin/python3 launch/py/paper_figures.py OUT_DIR --run LABEL=RUN_DIR [--run ...] \
      --fig3 LABEL --fig4 SBM_LABEL PBM_LABEL --glevels LABEL:N [LABEL:N ...] --fig7 LABEL --d-f D_F

Each figure is written as figN_*.csv and figN_*.png in OUT_DIR, plus summary.csv (one row per
run: peak load, initial stiffness, displacement at the peak, bond counts after penetration).

Initial stiffness k50: least-squares slope of load against footing displacement over the rising
branch, from the first contact (first row with load > 0) to the first row at half the first peak load
(first peak: the largest load before the load first falls below half of the largest so far, within
0.02 D_f of the first contact); the same rule as
tests/coupled/coupled_checks_test.cpp (docs/paper-study.md).
Elastic initial stiffness k_e: the same slope from the first contact to the last row before the
first ball-ball bond leaves the intact state (column dem.bond_failures; empty for runs recorded
before the column existed), also as in the test.
"""
import argparse
import csv
import os

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PEAK_WINDOW = 0.02  # [D_f] how far after the first contact the first peak is sought
INITIAL_PART = 0.05  # [D_f] span of the initial-part figure (Fig. 6)
STATE_NAMES = {1: "intact", 2: "softening", 3: "broken_tension", 4: "broken_shear"}


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError("%s: no rows" % path)
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def history_path(run):
    p = os.path.join(run, "history_4_penetrate.csv")
    return p if os.path.exists(p) else os.path.join(run, "history_5_penetrate.csv")


def curve(run):
    h = read_csv(history_path(run))
    return h["dem.footing_disp_m"], h["dem.footing_fz_N"]


def initial_stiffness(disp, load, d_f):
    """k50 [N/m]: least-squares slope of the rising branch, from the first contact (first row with
    load > 0) to the first row at half the first peak load (first peak: the largest load before
    the load first falls below half of the largest so far, within PEAK_WINDOW D_f of the first
    contact); returns (slope, intercept [N], first-contact
    displacement, displacement at half the first peak)."""
    hit = np.nonzero(load > 0)[0]
    if len(hit) == 0:
        return float("nan"), float("nan"), float("nan"), float("nan")
    i0 = hit[0]
    dc = disp[i0]
    ip = i = i0
    while i < len(disp) and disp[i] <= dc + PEAK_WINDOW * d_f:
        if load[i] > load[ip]:
            ip = i
        elif load[i] < 0.5 * load[ip]:
            break  # the first particle-scale failure
        i += 1
    ih = i0 + int(np.nonzero(load[i0:ip + 1] >= 0.5 * load[ip])[0][0])
    if ih - i0 + 1 < 5:
        return float("nan"), float("nan"), float(dc), float(disp[ih])
    k, b = np.polyfit(disp[i0:ih + 1], load[i0:ih + 1], 1)
    return float(k), float(b), float(dc), float(disp[ih])


def elastic_branch(load, failed):
    """(i0, ie): the elastic branch of a footing curve, from the first row with a load to the last
    row before the first ball-ball bond failure (failed: the cumulative dem.bond_failures); None
    when the footing never carried a load. The rule of k_e in every tool (and of the
    coordinator's result, coordinator/core/results.cpp)."""
    hit = np.nonzero(load > 0)[0]
    if len(hit) == 0:
        return None
    i0 = ie = int(hit[0])
    while ie + 1 < len(load) and failed[ie + 1] <= failed[i0]:
        ie += 1
    return i0, ie


def elastic_stiffness(run):
    """k_e [N/m] and the load [N] at the end of the elastic branch (first contact to the last row
    before the first bond failure); (nan, nan) without the dem.bond_failures column or with fewer
    than 5 rows."""
    h = read_csv(history_path(run))
    if "dem.bond_failures" not in h:
        return float("nan"), float("nan")
    disp, load, failed = h["dem.footing_disp_m"], h["dem.footing_fz_N"], h["dem.bond_failures"]
    branch = elastic_branch(load, failed)
    if branch is None:
        return float("nan"), float("nan")
    i0, ie = branch
    if ie - i0 + 1 < 5:
        return float("nan"), float(load[ie])
    return float(np.polyfit(disp[i0:ie + 1], load[i0:ie + 1], 1)[0]), float(load[ie])


def write_csv(path, names, cols):
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for row in zip(*cols):
            f.write(",".join(str(v) for v in row) + "\n")


def fig3(out, run, label):
    dem = read_csv(os.path.join(run, "dem_profile_gravity.csv"))
    fdm = read_csv(os.path.join(run, "fdm_profile_gravity.csv"))
    names = ["source", "depth_m", "szz_Pa", "selfweight_szz_Pa"]
    src = ["dem"] * len(dem["depth_m"]) + ["fdm"] * len(fdm["depth_m"])
    write_csv(os.path.join(out, "fig3_stress_depth.csv"), names,
              [src, np.r_[dem["depth_m"], fdm["depth_m"]], np.r_[dem["szz_Pa"], fdm["szz_Pa"]],
               np.r_[dem["selfweight_szz_Pa"], fdm["selfweight_szz_Pa"]]])
    fig, ax = plt.subplots(figsize=(5, 6))
    ax.plot(-fdm["szz_Pa"] * 1e-3, fdm["depth_m"] * 1e3, "s-", label="FDM zones (layer average)")
    ax.plot(-dem["szz_Pa"] * 1e-3, dem["depth_m"] * 1e3, "o-", label="DEM block (slabs)")
    d = np.linspace(0, fdm["depth_m"].max(), 50)
    rho, g_rho = fdm["rho_kg_m3"][0], -fdm["selfweight_szz_Pa"][0] / fdm["depth_m"][0]
    ax.plot(g_rho * d * 1e-3, d * 1e3, "k--", label=r"$\rho_b N g\,$depth ($\rho_b$=%g kg/m$^3$)" % rho)
    ax.invert_yaxis()
    ax.set_xlabel("vertical stress [kPa]")
    ax.set_ylabel("depth [mm]")
    ax.set_title("Fig. 3: stress after gravity equilibrium (%s)" % label)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig3_stress_depth.png"), dpi=120)
    plt.close(fig)


def load_figure(out, stem, title, runs, labels, d_f, initial=False):
    names, cols = ["label", "disp_m", "load_N"], [[], [], []]
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for lab in labels:
        d, f = curve(runs[lab])
        cols[0] += [lab] * len(d)
        cols[1] += list(d)
        cols[2] += list(f)
        if initial:
            k, b, dc, dp = initial_stiffness(d, f, d_f)
            m = d <= dc + INITIAL_PART * d_f
            line, = ax.plot(d[m] * 1e3, f[m], label="%s (k50 %.3g N/m)" % (lab, k))
            if np.isfinite(k):
                dd = np.array([dc, dp])
                ax.plot(dd * 1e3, k * dd + b, "--", color=line.get_color())
        else:
            ax.plot(d * 1e3, f, label=lab)
    write_csv(os.path.join(out, stem + ".csv"), names, cols)
    ax.set_xlabel("footing displacement [mm]")
    ax.set_ylabel("footing load [N]")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, stem + ".png"), dpi=120)
    plt.close(fig)


def bond_state(run):
    import h5py

    with h5py.File(os.path.join(run, "dem.h5"), "r") as h:
        last = sorted(h["frames"])[-1]
        fr = h["frames"][last]
        return fr["particles/position"][()], fr["bonds/nodes"][()], fr["bonds/state"][()]


def fig7(out, run, label, footing_axis):
    x, nodes, state = bond_state(run)
    counts = {n: int((state == s).sum()) for s, n in STATE_NAMES.items()}
    write_csv(os.path.join(out, "fig7_bond_counts.csv"), ["state", "count_1"],
              [list(counts), list(counts.values())])
    mid = 0.5 * (x[nodes[:, 0]] + x[nodes[:, 1]])
    yc = footing_axis[1] if footing_axis is not None else 0.5 * (x[:, 1].min() + x[:, 1].max())
    band = 0.15 * (x[:, 1].max() - x[:, 1].min())
    sel = np.abs(mid[:, 1] - yc) <= band
    fig, ax = plt.subplots(figsize=(5, 8))
    style = {1: ("0.75", 4, "intact"), 2: ("tab:orange", 10, "softening"), 3: ("tab:blue", 14, "broken in tension"),
             4: ("tab:red", 14, "broken in shear")}
    for s, (c, size, name) in style.items():
        m = sel & (state == s)
        ax.scatter(mid[m, 0] * 1e3, mid[m, 2] * 1e3, s=size, c=c, label="%s (%d in all)" % (name, counts[STATE_NAMES[s]]))
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title("Fig. 7: bonds after penetration (%s),\nslice |y - y_c| < %.2f mm" % (label, band * 1e3))
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig7_bonds.png"), dpi=120)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--run", action="append", default=[], help="LABEL=RUN_DIR")
    ap.add_argument("--fig3")
    ap.add_argument("--fig4", nargs=2)
    ap.add_argument("--glevels", nargs="+", default=[], help="LABEL:N")
    ap.add_argument("--fig7")
    ap.add_argument("--d-f", type=float, required=True, help="footing diameter [m]")
    a = ap.parse_args()
    runs = {}
    for r in a.run:
        lab, _, d = r.partition("=")
        if not d or not os.path.isdir(d):
            ap.error("--run %s: expected LABEL=RUN_DIR of an existing folder" % r)
        runs[lab] = d
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for lab, d in runs.items():
        disp, load = curve(d)
        k, _, dc, dp = initial_stiffness(disp, load, a.d_f)
        i = int(np.argmax(load))
        _, _, state = bond_state(d)
        ke, fe = elastic_stiffness(d)
        rows.append([lab, float(load[i]), float(disp[i]), k, dc, dp, float(disp[-1]), ke, fe] +
                    [int((state == s).sum()) for s in STATE_NAMES])
    write_csv(os.path.join(a.out, "summary.csv"),
              ["label", "peak_load_N", "disp_at_peak_m", "initial_stiffness_N_m", "first_contact_m", "half_first_peak_m",
               "final_disp_m", "elastic_stiffness_N_m", "first_bond_failure_load_N"] +
              ["bonds_%s_1" % n for n in STATE_NAMES.values()], list(zip(*rows)))
    if a.fig3:
        fig3(a.out, runs[a.fig3], a.fig3)
    if a.fig4:
        load_figure(a.out, "fig4_load_sbm_pbm", "Fig. 4: load-displacement, SBM vs PBM", runs, a.fig4, a.d_f)
    if a.glevels:
        labs = [g.split(":")[0] for g in a.glevels]
        load_figure(a.out, "fig5_load_glevels", "Fig. 5: load-displacement at each g-level", runs, labs, a.d_f)
        load_figure(a.out, "fig6_load_glevels_initial", "Fig. 6: initial part", runs, labs, a.d_f, initial=True)
    if a.fig7:
        fig7(a.out, runs[a.fig7], a.fig7, None)
    for r in rows:
        print("%-12s peak %.4g N at %.4g mm, initial stiffness k50 %.4g N/m, k_e %.4g N/m (to %.3g N)" %
              (r[0], r[1], r[2] * 1e3, r[3], r[7], r[8]))


if __name__ == "__main__":
    main()

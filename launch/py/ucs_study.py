#!/usr/bin/python3
"""Tables and figure of the UCS scale-effect study (launch/study ucs; docs/ucs-study.md).

Usage: /usr/bin/python3 launch/py/ucs_study.py STUDY_DIR

Reads every run folder of STUDY_DIR (scene.toml, specimen_stages.csv, ucs_result.csv,
ucs_curve.csv, run_wall_s.txt) and writes
  ucs_runs.csv          one row per run (model, scale, seed, N_p, n, Z, E50, UCS, times)
  ucs_table.md          N_p, n, Z beside the paper's Table 1; E50 and UCS per scale (mean over
                        seeds) and their ratio to soft bond at scale 1
  ucs_stress_strain.png axial stress against axial strain for every run (like Fig. 1)
Only numpy and matplotlib (Agg backend).
"""
import csv
import os
import sys
import tomllib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Table 1 of the paper (docs/theory.md 0.3): N_p in 4 x 4 x 2 mm; n and Z where the paper gives them.
TABLE1 = {1.0: (25835, 0.5195, 6.82), 1.3: (11781, None, None), 1.5: (7664, 0.52042, None)}


def read_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def run_record(d):
    with open(os.path.join(d, "scene.toml"), "rb") as f:
        scene = tomllib.load(f)
    dem = scene.get("dem", {})
    rec = {
        "run": os.path.basename(d),
        "model": dem.get("ball_ball", {}).get("model", "softbond"),
        "scale": float(dem.get("specimen", {}).get("scale", 1.5)),
        "seed": int(scene.get("run", {}).get("seed", 1)),
    }
    stages = read_rows(os.path.join(d, "specimen_stages.csv"))
    periodic = [r for r in stages if float(r["porosity_unit"]) > 0]
    last = periodic[-1]  # the servoed REV, before it is opened
    rec.update(balls=int(last["balls_unit"]), porosity=float(last["porosity_unit"]),
               z=float(last["coordination_unit"]), z_no_rattlers=float(last["coordination_no_rattlers_unit"]),
               servo_converged=int(last["converged_unit"]), servo_ratio=float(last["ratio_unit"]),
               szz_Pa=float(last["szz_Pa"]), sxx_Pa=float(last["sxx_Pa"]))
    u = read_rows(os.path.join(d, "ucs_result.csv"))[0]
    rec.update(ucs_Pa=float(u["ucs_Pa"]), e50_Pa=float(u["e50_Pa"]), peak_strain=float(u["peak_strain_unit"]),
               z_ucs=float(u["coordination_unit"]), broken_t=int(u["bonds_broken_tension_unit"]),
               broken_s=int(u["bonds_broken_shear_unit"]), ucs_steps=int(u["ucs_steps_unit"]),
               ucs_wall_s=float(u["ucs_wall_s"]), ucs_cpu_s=float(u["ucs_cpu_s"]),
               peak_reached=int(u["peak_reached_unit"]))
    rec["s_per_step"] = rec["ucs_wall_s"] / max(rec["ucs_steps"], 1)
    wall = os.path.join(d, "run_wall_s.txt")
    rec["run_wall_s"] = float(open(wall).read()) if os.path.exists(wall) else float("nan")
    curve = read_rows(os.path.join(d, "ucs_curve.csv"))
    rec["curve"] = ([float(r["strain_unit"]) for r in curve], [float(r["stress_Pa"]) for r in curve])
    return rec


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def main(study):
    runs = []
    for name in sorted(os.listdir(study)):
        d = os.path.join(study, name)
        if os.path.isdir(d) and os.path.exists(os.path.join(d, "ucs_result.csv")):
            runs.append(run_record(d))
    if not runs:
        sys.exit(f"ucs_study: no finished UCS run in {study}")
    keys = [k for k in runs[0] if k != "curve"]
    with open(os.path.join(study, "ucs_runs.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in runs:
            w.writerow({k: r[k] for k in keys})

    groups = {}
    for r in runs:
        groups.setdefault((r["model"], r["scale"]), []).append(r)

    def mean(g, k):
        return sum(r[k] for r in g) / len(g)

    ref = groups.get(("softbond", 1.0))
    lines = ["# UCS study: specimen (Table 1) and macro response (Fig. 1)", "",
             "Means over seeds. Paper values from Table 1 (docs/theory.md 0.3); '-' where the paper gives none.",
             "Z is the coordination number of the servoed periodic REV (bonded pairs, docs/ucs-study.md).", "",
             "| model | scale | seeds | N_p | N_p paper | dN_p | n | n paper | Z | Z paper | servo ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for (model, scale), g in sorted(groups.items(), key=lambda x: (x[0][0], -x[0][1])):
        np_ref, n_ref, z_ref = TABLE1.get(scale, (None, None, None))
        npm = mean(g, "balls")
        lines.append(f"| {model} | {scale:g} | {len(g)} | {npm:.0f} | {fmt(np_ref, 'd')} | "
                     f"{fmt(None if np_ref is None else 100 * (npm / np_ref - 1), '+.2f')} % | {mean(g, 'porosity'):.4f} | "
                     f"{fmt(n_ref, '.4f')} | {mean(g, 'z'):.3f} | {fmt(z_ref, '.2f')} | {max(r['servo_ratio'] for r in g):.1e} |")
    lines += ["", "| model | scale | seeds | E50 [MPa] | UCS [MPa] | strain at peak [%] | E50 / E50(SBM, 1) | "
              "UCS / UCS(SBM, 1) | peak reached | s/step | UCS stage wall [s] |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for (model, scale), g in sorted(groups.items(), key=lambda x: (x[0][0], -x[0][1])):
        e, u = mean(g, "e50_Pa"), mean(g, "ucs_Pa")
        re = fmt(None if ref is None else e / mean(ref, "e50_Pa"), ".3f")
        ru = fmt(None if ref is None else u / mean(ref, "ucs_Pa"), ".3f")
        lines.append(f"| {model} | {scale:g} | {len(g)} | {e / 1e6:.1f} | {u / 1e6:.3f} | {100 * mean(g, 'peak_strain'):.3f} | "
                     f"{re} | {ru} | {sum(r['peak_reached'] for r in g)}/{len(g)} | {mean(g, 's_per_step'):.2e} | "
                     f"{mean(g, 'ucs_wall_s'):.0f} |")
    if ref is None:
        lines += ["", "Soft bond at scale 1 was not run: no ratios to scale 1."]
    text = "\n".join(lines) + "\n"
    open(os.path.join(study, "ucs_table.md"), "w").write(text)
    print(text)

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    colours = {1.0: "tab:blue", 1.3: "tab:orange", 1.5: "tab:green"}
    for r in runs:
        x, y = r["curve"]
        style = "-" if r["model"] == "softbond" else "--"
        label = f"{'SBM' if r['model'] == 'softbond' else 'PBM'} scale {r['scale']:g} seed {r['seed']}"
        ax.plot([100 * v for v in x], [v / 1e6 for v in y], style, color=colours.get(r["scale"], "k"), label=label)
    ax.set_xlabel("axial strain [%]")
    ax.set_ylabel("axial stress [MPa]")
    ax.set_title("Unconfined compression, 4 x 4 x 2 mm")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(study, "ucs_stress_strain.png"), dpi=150)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])

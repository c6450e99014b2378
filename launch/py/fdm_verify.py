"""Compare the FDM verification runs of launch/studies/fdm_verify.sh with closed forms.

fdm_column (physics.md 8.11): sigma_zz(z) = -rho N g0 (H - z) at zone centroids, base reaction
= weight, u_top = -rho N g0 H^2 / (2 M). fdm_punch (8.13): K = 2 a E / (1 - nu^2) for a
half-space (the strongbox is a few per cent stiffer). Prints a Markdown table and writes it
to <study>/fdm_verification.md; exits 1 if a case misses its tolerance.
"""
import csv
import sys
from pathlib import Path

import h5py
import numpy as np


def last(h5, group):
    frames = sorted(h5["frames"].keys())
    return h5["frames"][frames[-1]][group]


def column(run: Path):
    rho, n, g0, e, nu, h = 1272.0, 100.0, 9.81, 2.0e9, 0.25, 10e-3
    k, g = e / (3 * (1 - 2 * nu)), e / (2 * (1 + nu))
    m = k + 4 * g / 3
    with h5py.File(run / "fdm.h5", "r") as f:
        xyz = f["mesh/node_coords"][:]
        zones = f["mesh/zone_nodes"][:]
        zc = xyz[zones].mean(axis=1)[:, 2]
        s = last(f, "zones")["stress"][:]
        u = last(f, "nodes")["displacement"][:]
    exact = -rho * n * g0 * (h - zc)
    err_s = np.max(np.abs(s[:, 2] - exact)) / (rho * n * g0 * h)
    top = np.isclose(xyz[:, 2], h)
    u_top = u[top, 2].mean()
    u_exact = -rho * n * g0 * h * h / (2 * m)
    rows = list(csv.DictReader(open(run / "fdm_history.csv")))
    weight = rho * n * g0 * 2e-3 * 2e-3 * h
    base = float(rows[-1]["base_fz_N"])
    return [
        ("column: max abs(sigma_zz - rho N g (H-z)) / (rho N g H)", err_s, 0.01),
        ("column: u_top / closed form - 1", abs(u_top / u_exact - 1), 0.01),
        ("column: base reaction / weight - 1", abs(base / weight - 1), 0.005),
    ]


def punch(run: Path):
    a, e, nu = 0.6e-3, 2.0e9, 0.25
    k0 = 2 * a * e / (1 - nu * nu)
    rows = list(csv.DictReader(open(run / "fdm_history.csv")))
    f = -float(rows[-1]["punch_fz_N"])
    d = float(rows[-1]["punch_disp_m"])
    return [("punch: K / (2aE/(1-nu^2)) - 1 (box stiffening expected, +1..5 %)", abs(f / d / k0 - 1), 0.05)]


def main():
    study = Path(sys.argv[1])
    cases = column(study / "fdm_column") + punch(study / "fdm_punch")
    lines = ["| case | error | tolerance | ok |", "|---|---|---|---|"]
    ok = True
    for name, err, tol in cases:
        lines.append(f"| {name} | {err:.3e} | {tol:g} | {'yes' if err <= tol else 'NO'} |")
        ok &= err <= tol
    text = "\n".join(lines) + "\n"
    (study / "fdm_verification.md").write_text(text)
    print(text)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()

"""Compare the FDM verification runs of launch/studies/fdm_verify.sh with closed forms.

fdm_column (docs/theory.md 8.11): sigma_zz(z) = -rho N g0 (H - z) at zone centroids, base reaction
= weight, u_top = -rho N g0 H^2 / (2 M). fdm_punch (8.13): K = 2 a E / (1 - nu^2) for a
half-space (the strongbox is a few per cent stiffer). fdm_wave (8.12): P-wave speed in a
rollered column within 2 %. fdm_triaxial (8.15): Mohr-Coulomb peak within 1 %. Prints a Markdown table and writes it
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


def wave(run: Path):
    """Arrival of the half-amplitude pulse front at 5, 10, 15 mm depth (linear interpolation
    between frames); speed over the two 5 mm spans against C_p = sqrt(M / rho)."""
    e, nu, rho, h, v0 = 2.0e9, 0.25, 1272.0, 20e-3, 0.01
    m = e / (3 * (1 - 2 * nu)) + 4 * e / (2 * (1 + nu)) / 3
    cp = (m / rho) ** 0.5
    with h5py.File(run / "fdm.h5", "r") as f:
        z = f["mesh/node_coords"][:, 2]
        names = sorted(f["frames"].keys())
        t = np.array([f["frames"][n].attrs["time"] for n in names])
        vz = np.array([f["frames"][n]["nodes"]["velocity"][:, 2] for n in names])
    arrival = []
    for d in (5e-3, 10e-3, 15e-3):
        layer = np.isclose(z, h - d)
        front = -vz[:, layer].mean(axis=1) / v0  # 0 before, 1 in the pulse
        i = int(np.argmax(front >= 0.5))
        arrival.append(t[i - 1] + (0.5 - front[i - 1]) / (front[i] - front[i - 1]) * (t[i] - t[i - 1]))
    c1 = 5e-3 / (arrival[1] - arrival[0])
    c2 = 5e-3 / (arrival[2] - arrival[1])
    return [
        (f"wave: speed 5-10 mm ({c1:.1f} m/s) / C_p ({cp:.1f} m/s) - 1", abs(c1 / cp - 1), 0.02),
        (f"wave: speed 10-15 mm ({c2:.1f} m/s) / C_p - 1", abs(c2 / cp - 1), 0.02),
    ]


def triaxial(run: Path):
    """Strength of the Mohr-Coulomb triaxial test against s3 N_phi + 2 c sqrt(N_phi). The model is
    perfectly plastic, so the strength is the plateau: the mean axial stress over the last 10 %
    of the loading (the running maximum includes the mass-scaled dynamics' small overshoot)."""
    import math
    s3, c, phi, area = 0.2e6, 0.1e6, math.radians(30.0), 1.5e-3 ** 2
    nphi = (1 + math.sin(phi)) / (1 - math.sin(phi))
    exact = s3 * nphi + 2 * c * math.sqrt(nphi)
    rows = list(csv.DictReader(open(run / "fdm_history.csv")))
    tail = rows[-max(1, len(rows) // 10):]
    peak = sum(-float(r["punch_fz_N"]) for r in tail) / len(tail) / area
    return [(f"triaxial: plateau sigma_1 ({peak / 1e6:.4f} MPa) / closed form ({exact / 1e6:.4f} MPa) - 1",
             abs(peak / exact - 1), 0.01)]


def main():
    study = Path(sys.argv[1])
    cases = (column(study / "fdm_column") + punch(study / "fdm_punch") + wave(study / "fdm_wave") +
             triaxial(study / "fdm_triaxial"))
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

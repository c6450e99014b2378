#!/usr/bin/python3
"""ctest bench_vs_lammps: bench/dem/vs_lammps.py in a quick mode (50 steps, 1 round).

Run 1 (LAMMPS as found on PATH): the figures of both models are positive numbers; when lmp or
lmp_serial is on PATH the two ratio lines carry a positive median and a verdict, the LAMMPS
row of the table is filled and the "LAMMPS not installed" line is absent; without it that line
is there and no ratio line is. Run 2 (--lmp pointing nowhere): always the "LAMMPS not installed"
line, no ratio line, exit 0, our figures. Both: the pair kernel and the CPU's ISA are named, the
phase shares are within 0-100 % with the pair pass the largest, the hardware-estimate line has
three positive times and a distance, the host-load line gives ordered ranges of the hardware
figures (and LAMMPS's spread exactly when it ran), the moving run reports >= 1 neighbour
rebuild and a share, and the CSV has one row per run.
Usage: check_vs_lammps.py REPO_ROOT   (env DEMFDM_BUILD: the build folder holding bin/bench_dem)
"""
import csv
import os
import re
import shutil
import subprocess
import sys
import tempfile

root = sys.argv[1]
script = os.path.join(root, "bench", "dem", "vs_lammps.py")
fails = []


def check(cond, what):
    if not cond:
        fails.append(what)
    return cond


def run(extra, tmp, tag):
    out_csv = os.path.join(tmp, tag + ".csv")
    cmd = ["/usr/bin/python3", script, "--steps", "50", "--rounds", "1", "--period", "10", "--csv", out_csv] + extra
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=110)
    print("$ " + " ".join(cmd))
    print(p.stdout)
    if p.stderr:
        print(p.stderr, file=sys.stderr)
    check(p.returncode == 0, "%s: exit %d" % (tag, p.returncode))
    return p.stdout, out_csv


def common(out, out_csv, tag, with_lammps):
    m = re.search(r"^cpu: .*ISA (avx512f|avx2|sse2 only) \((AVX-512 present|no AVX-512)\), clock ([0-9.]+) GHz", out,
                  re.M)
    if check(m is not None, tag + ": cpu line with ISA and clock"):
        check(float(m.group(3)) > 0.3, tag + ": clock > 0.3 GHz")
    m = re.search(r"^median\s+(\S+)\s+([0-9.e+]+)\s+([0-9.e+]+)\s+(\S+)\s+(\S+)$", out, re.M)
    if check(m is not None, tag + ": median row of the table"):
        check(float(m.group(2)) > 1e4 and float(m.group(3)) > 1e4, tag + ": linear and soft bond figures > 1e4")
        if with_lammps:
            check(float(m.group(1)) > 1e4, tag + ": LAMMPS figure > 1e4")
            check(float(m.group(4)) > 0 and float(m.group(5)) > 0, tag + ": ratios in the median row")
        else:
            check(m.group(1) == "-" and m.group(4) == "-", tag + ": no LAMMPS column without LAMMPS")
    ratios = re.findall(r"^ratio (linear|softbond)/LAMMPS: median ([0-9.]+) \(rounds [0-9. ]+\); target "
                        r"([0-9.]+): (met|NOT met)$", out, re.M)
    missing = "LAMMPS not installed" in out
    if with_lammps:
        check(len(ratios) == 2, tag + ": two ratio lines with LAMMPS")
        check(all(float(r[1]) > 0 for r in ratios), tag + ": ratios > 0")
        check({r[0]: r[2] for r in ratios} == {"linear": "2.0", "softbond": "1.5"}, tag + ": targets 2.0 and 1.5")
        check(not missing, tag + ": no 'LAMMPS not installed' line when LAMMPS ran")
        check(re.search(r"^peak RSS .*LAMMPS [0-9.]+, linear [0-9.]+, soft bond [0-9.]+; not above LAMMPS's: "
                        r"(met|NOT met)$", out, re.M) is not None, tag + ": RSS line with verdict")
    else:
        check(len(ratios) == 0, tag + ": no ratio line without LAMMPS")
        check(missing, tag + ": 'LAMMPS not installed' line")
    m = re.search(r"^pair kernel: linear (\w+), soft bond (\w+) \(CPU ISA (\w+)\)$", out, re.M)
    if check(m is not None, tag + ": pair kernel line"):
        check(m.group(1) in ("avx512", "avx2", "baseline", "scalar"), tag + ": kernel named")
    for model in ("linear", "softbond"):
        m = re.search(r"^  %s\s+([0-9.]+) ms/step: pair ([0-9.]+) %%, neighbour check\+rebuild ([0-9.]+) %%, "
                      r"motion ([0-9.]+) %%" % model, out, re.M)
        if check(m is not None, tag + ": phase line " + model):
            ms, pair, reb, mot = (float(g) for g in m.groups())
            check(ms > 0, tag + ": ms/step > 0")
            check(50 < pair <= 100 and 0 <= reb <= 100 and 0 < mot < 50, tag + ": phase shares of " + model)
        m = re.search(r"^  %s\s+pair pass ([0-9.]+) ns = ([0-9]+) cycles per active contact \((\d+) active\)" % model,
                      out, re.M)
        if check(m is not None, tag + ": ns/cycles per contact " + model):
            check(float(m.group(1)) > 0 and int(m.group(2)) > 0 and int(m.group(3)) > 50000,
                  tag + ": per-contact figures of " + model)
    m = re.search(r"^contact pass \(linear\): ([0-9.]+) ns/contact measured; bandwidth bound ([0-9.]+) ns; flop "
                  r"bound ([0-9.]+) ns; distance ([0-9.]+)x$", out, re.M)
    if check(m is not None, tag + ": hardware-estimate line"):
        meas, bw, fl, dist = (float(g) for g in m.groups())
        check(meas > 0 and bw > 0 and fl > 0, tag + ": estimate times > 0")
        check(abs(dist - meas / max(bw, fl)) < 0.06 * dist + 0.05, tag + ": distance = measured / larger bound")
    m = re.search(r"^host load: over the (\d+) hardware measurements clock ([0-9.]+)-([0-9.]+) GHz, triad ([0-9.]+)-"
                  r"([0-9.]+) GB/s at [0-9.]+ MB, ([0-9.]+)-([0-9.]+) GB/s at 384 MiB(; LAMMPS's rounds ([0-9.e+]+)-"
                  r"([0-9.e+]+))?$", out, re.M)
    if check(m is not None, tag + ": host-load line"):
        check(int(m.group(1)) == 2, tag + ": two hardware measurements in one round")
        lo_hi = [(float(m.group(i)), float(m.group(i + 1))) for i in (2, 4, 6)]
        check(all(0 < lo <= hi for lo, hi in lo_hi), tag + ": host-load ranges ordered and positive")
        check((m.group(8) is not None) == with_lammps, tag + ": LAMMPS's spread exactly when LAMMPS ran")
    m = re.search(r"^moving: rebuilds (\d+) in (\d+) steps .* rebuild share ([0-9.]+) % of the step; target <= 15 %: "
                  r"(met|NOT met)$", out, re.M)
    if check(m is not None, tag + ": moving line"):
        check(int(m.group(1)) >= 1, tag + ": moving run rebuilt the neighbour list at least once")
        check(int(m.group(2)) == 50, tag + ": moving run of 50 steps")
        check(0 < float(m.group(3)) <= 100, tag + ": rebuild share in (0, 100] %")
    if check(os.path.exists(out_csv), tag + ": CSV written"):
        with open(out_csv) as f:
            rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
        codes = sorted(r["code"] for r in rows)
        want = sorted(["linear", "softbond", "moving"] + (["lammps", "lammps_moving"] if with_lammps else []))
        check(codes == want, tag + ": CSV rows %s, expected %s" % (codes, want))
        for r in rows:
            check(float(r["particle_steps_per_s_per_core"]) > 0, tag + ": CSV figure of " + r["code"])


have_lmp = any(shutil.which(n) for n in ("lmp", "lmp_serial"))
with tempfile.TemporaryDirectory(prefix="bench_speed_") as tmp:
    out, c = run([], tmp, "found")
    common(out, c, "found", have_lmp)
    out, c = run(["--lmp", os.path.join(tmp, "no-such-lmp")], tmp, "forced-missing")
    common(out, c, "forced-missing", False)

if fails:
    print("FAILED (%d):" % len(fails))
    for f in fails:
        print("  " + f)
    sys.exit(1)
print("bench_vs_lammps: OK (LAMMPS %s)" % ("found and compared" if have_lmp else "not installed"))

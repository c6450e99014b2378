#!/usr/bin/python3
"""Per core, against LAMMPS in the same run (issue 16 items 1 and 3, measurement part).

Runs LAMMPS's pair gran/hooke/history on the reference packing (bench/dem/data) with the
physics of bench_dem, interleaved with `bench_dem PACKING linear 1 STEPS` and
`bench_dem PACKING softbond 1 STEPS`, one process at a time, pinned to one CPU, for N rounds.
Prints per round and as medians the particle-steps per second per core of each, the ratios to
LAMMPS against the targets (linear >= 2.0x, soft bond >= 1.5x LAMMPS's unbonded figure), the
peak RSS of each, the pair kernel that ran and the CPU's instruction set; where the time goes
(phases, ns and cycles per contact of the pair pass); the distance of the contact pass to a
hardware estimate (bytes and flops per contact against the measured bandwidth, clock and
vector throughput); and a penetration-like run (`bench_dem ... moving`: the periodic cell
strained so that the neighbour list is rebuilt every few tens of steps) with the share of the
step spent in the neighbour search (target <= 15 %). Without LAMMPS (no `lmp` or
`lmp_serial`; Debian package `lammps`) it says so and prints our figures alone (exit 0).

Usage: vs_lammps.py [--rounds 3] [--steps 2000] [--bench PATH] [--csv OUT] [--bench-csv OUT]
                    [--lmp PATH] [--packing FILE] [--cpu N] [--period 30]
docs/speed.md explains every figure.
"""
import argparse
import csv
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
PACKING = os.path.join(HERE, "data", "bench_packing_25835.txt")

# bench_dem's physics (bench/dem/bench_dem.cpp): the same for LAMMPS.
KN = 2.55e5                     # N/m, every pair
KT = KN / 2.4                   # N/m (LAMMPS's Kt of the Hookean style is force/distance too)
MU = math.tan(math.radians(32))  # 0.6248693519...
RHO = 2650.0                    # kg/m3
TARGET_LINEAR = 2.0
TARGET_SOFTBOND = 1.5
TARGET_REBUILD_SHARE = 0.15


def fail(msg):
    print("vs_lammps: " + msg, file=sys.stderr)
    sys.exit(1)


def find_bench(arg):
    if arg:
        return arg
    build = os.environ.get("DEMFDM_BUILD") or os.path.join(ROOT, "build")
    return os.path.join(build, "bin", "bench_dem")


def find_lmp(arg):
    """(path, why-not). An explicit --lmp that does not exist counts as not installed."""
    if arg:
        if os.path.isfile(arg) and os.access(arg, os.X_OK):
            return arg, ""
        return None, "no executable at --lmp %s" % arg
    for name in ("lmp", "lmp_serial"):
        p = shutil.which(name)
        if p:
            return p, ""
    return None, "no lmp or lmp_serial on PATH; Debian: apt-get install lammps"


def cpu_info():
    model, flags, mhz = "?", set(), None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                k, _, v = line.partition(":")
                k = k.strip()
                if k == "model name" and model == "?":
                    model = v.strip()
                elif k == "flags" and not flags:
                    flags = set(v.split())
                elif k == "cpu MHz" and mhz is None:
                    mhz = float(v)
    except OSError:
        pass
    isa = "avx512f" if "avx512f" in flags else ("avx2" if "avx2" in flags else "sse2")
    return {"model": model, "avx2": "avx2" in flags, "avx512f": "avx512f" in flags, "isa": isa,
            "mhz": mhz, "cpus": os.cpu_count() or 1}


def kv(line):
    out = {}
    for tok in line.split():
        k, sep, v = tok.partition("=")
        if sep:
            try:
                out[k] = float(v)
            except ValueError:
                out[k] = v
    return out


class Runner:
    """Runs one process at a time, pinned to one CPU, under /usr/bin/time -v (peak RSS)."""

    def __init__(self, cpu, tmp):
        self.tmp = tmp
        self.pin = []
        if cpu >= 0 and shutil.which("taskset"):
            self.pin = ["taskset", "-c", str(cpu)]
        self.timer = "/usr/bin/time" if os.access("/usr/bin/time", os.X_OK) else None

    def run(self, cmd, env=None, cwd=None):
        rss_file = os.path.join(self.tmp, "time.txt")
        full = list(self.pin)
        if self.timer:
            full += [self.timer, "-v", "-o", rss_file]
        full += cmd
        e = dict(os.environ)
        e["OMP_NUM_THREADS"] = "1"
        e.update(env or {})
        p = subprocess.run(full, capture_output=True, text=True, env=e, cwd=cwd)
        if p.returncode != 0:
            fail("'%s' failed (exit %d):\n%s%s" % (" ".join(cmd), p.returncode, p.stdout[-2000:], p.stderr[-2000:]))
        rss = None
        if self.timer:
            with open(rss_file) as f:
                m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", f.read())
                rss = int(m.group(1)) / 1024.0 if m else None
        return p.stdout, p.stderr, rss


# ---- bench_dem ----------------------------------------------------------------------------

CSV_COLS = ("model,threads,steps,wall_s,cpu_s,particle_steps_per_s_wall,particle_steps_per_s_per_core_cpu,"
            "rebuilds_in_window,contacts,peak_rss_mib,pair_kernel,omp_wait_policy,kernel_isa").split(",")


def run_bench(runner, bench, packing, model, steps, period=None):
    cmd = [bench, packing, model, "1", str(steps)] + ([str(period)] if period else [])
    out, err, rss = runner.run(cmd, env={"BENCH_DEM_PHASES": "1"})
    row, raw = None, None
    for line in out.splitlines():
        f = line.strip().split(",")
        if len(f) >= 12 and f[0] == model:
            row, raw = dict(zip(CSV_COLS, f)), line.strip()
    if row is None:
        fail("no CSV line from bench_dem %s:\n%s" % (model, out))
    ph, mv = None, None
    for line in err.splitlines():
        if line.startswith("phases_kv "):
            ph = kv(line)
        elif line.startswith("moving "):
            mv = kv(line)
    if ph is None:
        fail("bench_dem printed no phases_kv line (BENCH_DEM_PHASES=1):\n" + err)
    r = {"code": model, "steps": steps, "wall": float(row["wall_s"]), "cpu": float(row["cpu_s"]),
         "per_core": float(row["particle_steps_per_s_per_core_cpu"]),
         "wall_rate": float(row["particle_steps_per_s_wall"]), "rss": rss if rss else float(row["peak_rss_mib"]),
         "kernel": row.get("kernel_isa", row["pair_kernel"]), "rebuilds": int(row["rebuilds_in_window"]),
         "phases": ph, "moving": mv, "raw": raw}
    return r


# ---- LAMMPS -------------------------------------------------------------------------------

def read_packing(path):
    with open(path) as f:
        lines = f.read().splitlines()
    lo, hi = [], []
    for l in lines[5:8]:
        a, b = l.split()[:2]
        lo.append(float(a))
        hi.append(float(b))
    atoms = []
    for l in lines[9:]:
        t = l.split()
        if len(t) >= 4:
            atoms.append(tuple(float(v) for v in t[:4]))
    return lo, hi, atoms


def write_lammps(tmp, packing, dt, skin, steps, erate=None):
    lo, hi, atoms = read_packing(packing)
    data = os.path.join(tmp, "packing.data")
    if not os.path.exists(data):
        with open(data, "w") as f:
            f.write("bench_dem reference packing (bench/dem/data), atom_style sphere, SI\n\n")
            f.write("%d atoms\n1 atom types\n\n" % len(atoms))
            for k, n in enumerate("xyz"):
                f.write("%.17g %.17g %slo %shi\n" % (lo[k], hi[k], n, n))
            f.write("\nAtoms # sphere\n\n")
            for i, (x, y, z, r) in enumerate(atoms):
                p = [x, y, z]
                for k in range(3):  # wrap into the periodic box
                    L = hi[k] - lo[k]
                    p[k] = lo[k] + (p[k] - lo[k]) % L
                f.write("%d 1 %.17g %.17g %.17g %.17g %.17g\n" % (i + 1, 2 * r, RHO, p[0], p[1], p[2]))
    name = "in.moving" if erate else "in.held"
    deform = ("fix 2 all deform 1 x erate %.9g y erate %.9g remap x\n" % (erate, -erate)) if erate else ""
    with open(os.path.join(tmp, name), "w") as f:
        f.write(
            "# LAMMPS input written by bench/dem/vs_lammps.py: bench_dem's physics on its packing\n"
            "units si\n"
            "atom_style sphere\n"
            "boundary p p p\n"
            "comm_modify vel yes\n"
            "read_data packing.data\n"
            "# Kn Kt gamma_n gamma_t xmu dampflag: linear springs, no viscous damping (bench_dem has\n"
            "# local damping 0.7 instead, which LAMMPS does not have; it costs both nothing per contact)\n"
            "pair_style gran/hooke/history %.9g %.9g 0.0 0.0 %.16g 0\n"
            "pair_coeff * *\n"
            "neighbor %.9g bin\n"
            "neigh_modify delay 0 every 1 check yes\n"
            "timestep %.9g\n"
            "fix 1 all nve/sphere\n"
            "%s"
            "thermo 100000\n"
            "run 20\n"
            "run %d\n" % (KN, KT, MU, skin, dt, deform, steps))
    return name


def run_lammps(runner, lmp, tmp, name, natoms, steps):
    out, err, rss = runner.run([lmp, "-in", name, "-log", "none", "-echo", "none", "-nocite"], cwd=tmp)
    loops = re.findall(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms", out)
    cpus = re.findall(r"([0-9.]+)% CPU use", out)
    if len(loops) < 2 or not cpus:
        fail("cannot read LAMMPS's timing:\n" + out[-3000:] + err[-2000:])
    loop = float(loops[-1][0])
    if int(loops[-1][2]) != steps:
        fail("LAMMPS ran %s steps, expected %d" % (loops[-1][2], steps))
    cpu_frac = float(cpus[-1]) / 100.0
    tail = out[out.rfind("Loop time of"):]
    sec = {}
    for m in re.finditer(r"^(Pair|Neigh|Comm|Output|Modify|Other)\s*\|\s*([0-9.eE+-]*)\s*\|\s*([0-9.eE+-]+)",
                         tail, re.M):
        sec[m.group(1)] = float(m.group(3))
    builds = re.findall(r"Neighbor list builds = (\d+)", out)
    danger = re.findall(r"Dangerous builds = (\d+)", out)
    neighs = re.findall(r"Total # of neighbors = (\d+)", out)
    mem = re.findall(r"Per MPI rank memory allocation \(min/avg/max\) = [0-9.]+ \| ([0-9.]+)", out)
    version = re.search(r"LAMMPS \(([^)]*)\)", out)
    cpu_s = loop * cpu_frac
    return {"code": "lammps", "steps": steps, "wall": loop, "cpu": cpu_s,
            "per_core": natoms * steps / cpu_s if cpu_s > 0 else float("nan"),
            "wall_rate": natoms * steps / loop, "rss": rss, "kernel": "-", "sections": sec,
            "rebuilds": int(builds[-1]) if builds else -1, "dangerous": int(danger[-1]) if danger else -1,
            "neighbors": int(neighs[-1]) if neighs else -1, "lmp_mib": float(mem[-1]) if mem else None,
            "version": version.group(1) if version else "?"}


# ---- clock -------------------------------------------------------------------------------

def perf_clock(bench):
    """GHz from `perf stat -e cycles,task-clock` around a busy bench_dem, or None (e.g. KVM)."""
    if not shutil.which("perf"):
        return None, "perf not installed"
    p = subprocess.run(["perf", "stat", "-x,", "-e", "cycles,task-clock", "--", bench, "--info"],
                       capture_output=True, text=True)
    cyc = clk = None
    for line in p.stderr.splitlines():
        f = line.split(",")
        if len(f) > 2 and f[2].startswith("cycles"):
            cyc = float(f[0]) if re.match(r"^[0-9.]+$", f[0]) else None
        if len(f) > 2 and f[2].startswith("task-clock"):
            clk = float(f[0]) if re.match(r"^[0-9.]+$", f[0]) else None  # ms
    if cyc and clk:
        return cyc / (clk * 1e6), "perf stat cycles / task-clock"
    return None, "perf cycles not supported here"


def med(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    return statistics.median(xs) if xs else float("nan")


def fmt(x, spec=".3g"):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


# ---- main ----------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--bench", help="bench_dem (default $DEMFDM_BUILD/bin/bench_dem, else build/bin/bench_dem)")
    ap.add_argument("--csv", help="write every run as a CSV row here")
    ap.add_argument("--bench-csv", help="write bench_dem's own CSV lines of every run here (its header first)")
    ap.add_argument("--lmp", help="LAMMPS executable (default: lmp or lmp_serial on PATH)")
    ap.add_argument("--packing", default=PACKING)
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin every run to (default: the last allowed; -1: none)")
    ap.add_argument("--period", type=int, default=30, help="moving run: steps for the cell edge to move skin/3")
    a = ap.parse_args()
    if a.rounds < 1 or a.steps < 1:
        fail("--rounds and --steps must be >= 1")
    bench = find_bench(a.bench)
    if not os.access(bench, os.X_OK):
        fail("no bench_dem at %s (build it: cmake --build build --target bench_dem)" % bench)
    cpu = a.cpu
    if cpu is None:
        allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
        cpu = allowed[-1]
    ci = cpu_info()
    lmp, why = find_lmp(a.lmp)

    with tempfile.TemporaryDirectory(prefix="vs_lammps_") as tmp:
        runner = Runner(cpu, tmp)
        info, _, _ = runner.run([bench, "--info", a.packing])
        inf = kv(next(l for l in info.splitlines() if l.startswith("info ")))
        hws = []

        def measure_hw():  # before the rounds and after each round: the best of each figure counts
            out, _, _ = runner.run([bench, "--hw", "%.0f" % inf["working_set_bytes"]])
            hws.append(kv(next(l for l in out.splitlines() if l.startswith("hw "))))

        def best_hw():
            h = dict(hws[0])
            for k in ("clock_ghz", "triad_ws_gbs", "triad_dram_gbs", "addmul_per_ns", "div_per_ns", "sqrt_per_ns"):
                h[k] = max(x[k] for x in hws)
            return h

        measure_hw()
        hw = best_hw()
        pghz, psrc = perf_clock(bench)
        ghz, gsrc = (pghz, psrc) if pghz else (hw["clock_ghz"], "dependent-add chain in bench_dem --hw (%s)" % psrc)
        n = int(inf["balls"])

        print("vs_lammps: %s, packing %s (%d balls), %d steps x %d rounds, one process at a time%s" % (
            bench, os.path.basename(a.packing), n, a.steps, a.rounds,
            (", pinned to CPU %d" % cpu) if runner.pin else ", not pinned (no taskset)"))
        print("cpu: %s, %d CPUs, ISA %s (%s), clock %.2f GHz (%s)%s" % (
            ci["model"], ci["cpus"], "avx512f" if ci["avx512f"] else ("avx2" if ci["avx2"] else "sse2 only"),
            "AVX-512 present" if ci["avx512f"] else "no AVX-512", ghz, gsrc,
            (", /proc/cpuinfo %.0f MHz" % ci["mhz"]) if ci["mhz"] else ""))
        if lmp:
            print("LAMMPS: %s, pair gran/hooke/history Kn %.4g Kt %.6g gamma_n 0 gamma_t 0 xmu %.6f, "
                  "dt %.6g s, skin %.4g m (bench_dem's), 1 process, 1 thread" % (lmp, KN, KT, MU, inf["dt"], inf["skin"]))
            name = write_lammps(tmp, a.packing, inf["dt"], inf["skin"], a.steps)
        else:
            print("LAMMPS not installed (%s): our figures alone" % why)

        runs = []
        order = (["lammps"] if lmp else []) + ["linear", "softbond"]
        for r in range(a.rounds):
            seq = order[r % len(order):] + order[:r % len(order)]  # rotate the order each round
            for code in seq:
                if code == "lammps":
                    x = run_lammps(runner, lmp, tmp, name, n, a.steps)
                else:
                    x = run_bench(runner, bench, a.packing, code, a.steps)
                x["round"] = r + 1
                runs.append(x)
                print("  round %d %-8s %.3e particle-steps/s per core (cpu %.2f s, wall %.2f s), peak RSS %s MiB%s" % (
                    r + 1, code, x["per_core"], x["cpu"], x["wall"], fmt(x["rss"], ".1f"),
                    ("" if code == "lammps" else ", kernel " + x["kernel"])), flush=True)
            measure_hw()
        hw = best_hw()
        if not pghz:
            ghz = hw["clock_ghz"]

        def by(code, r=None):
            return [x for x in runs if x["code"] == code and (r is None or x["round"] == r)]

        # ---- table ----
        print()
        print("particle-steps/s per core (process CPU time; LAMMPS: loop time x its %CPU use)")
        hdr = "%-7s %11s %11s %11s %14s %16s" % ("round", "LAMMPS", "linear", "soft bond", "linear/LAMMPS",
                                                  "soft bond/LAMMPS")
        print(hdr)
        ratios = {"linear": [], "softbond": []}
        for r in range(1, a.rounds + 1):
            l = by("lammps", r)
            lam = l[0]["per_core"] if l else None
            lin = by("linear", r)[0]["per_core"]
            sb = by("softbond", r)[0]["per_core"]
            rl = lin / lam if lam else None
            rs = sb / lam if lam else None
            if lam:
                ratios["linear"].append(rl)
                ratios["softbond"].append(rs)
                for x in by("linear", r) + by("softbond", r):
                    x["ratio"] = x["per_core"] / lam
            print("%-7d %11s %11s %11s %14s %16s" % (r, fmt(lam, ".3e"), fmt(lin, ".3e"), fmt(sb, ".3e"),
                                                      fmt(rl, ".2f"), fmt(rs, ".2f")))
        mlam = med([x["per_core"] for x in by("lammps")]) if lmp else None
        mlin = med([x["per_core"] for x in by("linear")])
        msb = med([x["per_core"] for x in by("softbond")])
        print("%-7s %11s %11s %11s %14s %16s" % ("median", fmt(mlam, ".3e"), fmt(mlin, ".3e"), fmt(msb, ".3e"),
                                                  fmt(med(ratios["linear"]), ".2f") if lmp else "-",
                                                  fmt(med(ratios["softbond"]), ".2f") if lmp else "-"))
        print()
        if lmp:
            for code, tgt, label in (("linear", TARGET_LINEAR, "linear/LAMMPS"),
                                     ("softbond", TARGET_SOFTBOND, "softbond/LAMMPS")):
                m = med(ratios[code])
                print("ratio %s: median %.2f (rounds %s); target %.1f: %s" % (
                    label, m, " ".join("%.2f" % x for x in ratios[code]), tgt, "met" if m >= tgt else "NOT met"))
            lr = med([x["rss"] for x in by("lammps")])
            lin_r = med([x["rss"] for x in by("linear")])
            sb_r = med([x["rss"] for x in by("softbond")])
            print("peak RSS [MiB] (/usr/bin/time -v): LAMMPS %s, linear %s, soft bond %s; not above LAMMPS's: %s" % (
                fmt(lr, ".1f"), fmt(lin_r, ".1f"), fmt(sb_r, ".1f"),
                "met" if max(lin_r, sb_r) <= lr else "NOT met"))
            l0 = by("lammps")[-1]
            print("LAMMPS %s: %d neighbour-list builds in the timed window (dangerous %d), %d neighbour pairs, "
                  "its own memory line %s MiB" % (l0["version"], l0["rebuilds"], l0["dangerous"], l0["neighbors"],
                                                 fmt(l0["lmp_mib"], ".1f")))
        else:
            print("peak RSS [MiB] (/usr/bin/time -v): linear %s, soft bond %s" % (
                fmt(med([x["rss"] for x in by("linear")]), ".1f"), fmt(med([x["rss"] for x in by("softbond")]), ".1f")))
        print("pair kernel: linear %s, soft bond %s (CPU ISA %s)" % (
            by("linear")[0]["kernel"], by("softbond")[0]["kernel"], ci["isa"]))
        print("neighbour rebuilds in the timed windows (held packing: 0 expected): %s" % ", ".join(
            "%s %d" % (c, sum(max(x["rebuilds"], 0) for x in by(c))) for c in order))

        # ---- where the time goes ----
        print()
        print("where the time goes (sum over rounds; shares of the timed wall time; clock %.2f GHz)" % ghz)
        ns_pass = {}
        for code in ("linear", "softbond"):
            xs = by(code)
            steps = sum(x["phases"]["steps"] for x in xs)
            wall = sum(x["phases"]["wall"] for x in xs)
            ph = {k: sum(x["phases"][k] for x in xs) for k in ("rebuild", "pair", "gather", "motion", "effects",
                                                                "plane", "facet", "footing", "sum")}
            active = xs[-1]["phases"]["active"]
            lst = xs[-1]["phases"]["list"]
            other = wall - ph["sum"]
            ns_c = ph["pair"] / steps / active * 1e9
            ns_e = ph["pair"] / steps / lst * 1e9
            print("  %-8s %.3f ms/step: pair %.1f %%, neighbour check+rebuild %.1f %%, motion %.1f %%, "
                  "walls+gather %.1f %%, effects %.1f %%, outside phases %.1f %%" % (
                      code, wall / steps * 1e3, 100 * ph["pair"] / wall, 100 * ph["rebuild"] / wall,
                      100 * ph["motion"] / wall, 100 * (ph["gather"] + ph["plane"] + ph["facet"] + ph["footing"]) / wall,
                      100 * ph["effects"] / wall, 100 * other / wall))
            print("  %-8s pair pass %.1f ns = %.0f cycles per active contact (%d active), %.1f ns = %.0f cycles per "
                  "list entry (%d)" % (code, ns_c, ns_c * ghz, active, ns_e, ns_e * ghz, lst))
            ns_pass[code] = ns_c
            for x in xs:
                x["ns_contact"] = x["phases"]["pair"] / x["phases"]["steps"] / x["phases"]["active"] * 1e9
        if lmp:
            ls = by("lammps")
            loop = sum(x["wall"] for x in ls)
            sec = {k: sum(x["sections"].get(k, 0.0) for x in ls) for k in ("Pair", "Neigh", "Comm", "Modify",
                                                                             "Output", "Other")}
            steps = sum(x["steps"] for x in ls)
            active = by("linear")[-1]["phases"]["active"]
            ns = sec["Pair"] / steps / active * 1e9
            print("  LAMMPS   %.3f ms/step: Pair %.1f %%, Neigh %.1f %%, Modify (nve/sphere) %.1f %%, Comm %.1f %%, "
                  "Other+Output %.1f %%; Pair %.1f ns = %.0f cycles per active contact" % (
                      loop / steps * 1e3, 100 * sec["Pair"] / loop, 100 * sec["Neigh"] / loop,
                      100 * sec["Modify"] / loop, 100 * sec["Comm"] / loop,
                      100 * (sec["Other"] + sec["Output"]) / loop, ns, ns * ghz))

        # ---- hardware estimate of the linear contact pass ----
        xs = by("linear")
        active = xs[-1]["phases"]["active"]
        lst = xs[-1]["phases"]["list"]
        idle = max(lst - active, 0)
        meas = ns_pass["linear"]
        bytes_step = inf["bytes_per_entry"] * lst + inf["bytes_per_ball"] * n
        bw_ns = bytes_step / hw["triad_ws_gbs"] / active  # GB/s = bytes/ns
        dram_ns = bytes_step / hw["triad_dram_gbs"] / active
        t_addmul = (active * inf["flops_live"] + idle * inf["flops_idle"]) / hw["addmul_per_ns"]
        t_divsqrt = active * (inf["sqrt_live"] / hw["sqrt_per_ns"] + inf["div_live"] / hw["div_per_ns"])
        flop_ns = max(t_addmul, t_divsqrt) / active
        bound = max(bw_ns, flop_ns)
        print()
        print("hardware (best of %d measurements, one before the rounds and one after each round): clock %.2f GHz, "
              "triad %.1f GB/s at %.1f MB, %.1f GB/s at 384 MiB; %s %.1f + or x, %.2f div, %.2f sqrt per ns" % (
                  len(hws), hw["clock_ghz"], hw["triad_ws_gbs"], inf["working_set_bytes"] / 1e6, hw["triad_dram_gbs"],
                  hw["isa"], hw["addmul_per_ns"], hw["div_per_ns"], hw["sqrt_per_ns"]))
        print("contact pass (linear): %.1f ns/contact measured; bandwidth bound %.1f ns; flop bound %.1f ns; "
              "distance %.1fx" % (meas, bw_ns, flop_ns, meas / bound))
        print("  assumptions: per list entry %.0f B (a, b, image shift; the %d-B ContactHist read and written back), "
              "per ball %.0f B (x, v, w, R read; f, t zeroed and accumulated), once per step: %.0f B per active "
              "contact (%d active of %d list entries); working set %.1f MB streamed at the triad bandwidth measured "
              "at that size, %.1f GB/s (at 384 MiB, DRAM: %.1f GB/s -> %.1f ns)" % (
                  inf["bytes_per_entry"], int(inf["contact_hist_bytes"]), inf["bytes_per_ball"], bytes_step / active,
                  active, lst, inf["working_set_bytes"] / 1e6, hw["triad_ws_gbs"], hw["triad_dram_gbs"], dram_ns))
        print("  flops: %d + - x, %d sqrt, %d div per live contact and %d per idle entry (counted from the linear "
              "lane loop); measured on this core at %s (%d lanes): %.1f + or x per ns, %.2f div per ns, %.2f sqrt per "
              "ns; bound = max(+-x time %.1f ns, div+sqrt time %.1f ns) per contact; %.0f cycles per contact "
              "measured at %.2f GHz" % (
                  int(inf["flops_live"]), int(inf["sqrt_live"]), int(inf["div_live"]), int(inf["flops_idle"]),
                  hw["isa"], int(hw["lanes"]), hw["addmul_per_ns"], hw["div_per_ns"], hw["sqrt_per_ns"],
                  t_addmul / active, t_divsqrt / active, meas * ghz, ghz))

        # ---- how busy the host was ----
        # The rounds are interleaved, but a host whose other tenants load the shared cache and
        # memory slows LAMMPS more than bench_dem (docs/speed.md, session 35: from a quiet to a
        # busy hour LAMMPS fell 35 %, the linear pass 27 %), so the ratios read high there.
        def span(vals):
            return min(vals), max(vals)
        c0, c1 = span([x["clock_ghz"] for x in hws])
        w0, w1 = span([x["triad_ws_gbs"] for x in hws])
        d0, d1 = span([x["triad_dram_gbs"] for x in hws])
        line = ("host load: over the %d hardware measurements clock %.2f-%.2f GHz, triad %.1f-%.1f GB/s at %.1f MB, "
                "%.1f-%.1f GB/s at 384 MiB" % (len(hws), c0, c1, w0, w1, inf["working_set_bytes"] / 1e6, d0, d1))
        busy = d1 > 1.15 * d0 or w1 > 1.15 * w0
        if lmp:
            l0, l1 = span([x["per_core"] for x in by("lammps")])
            line += "; LAMMPS's rounds %.3e-%.3e" % (l0, l1)
            busy = busy or l1 > 1.15 * l0
        print()
        print(line)
        if busy and lmp:
            print("  the host was busy (a spread above 15 %): other tenants slow LAMMPS more than bench_dem, so the "
                  "ratios read high; compare ratios measured at the same host load (docs/speed.md)")
        elif busy:
            print("  the host was busy (a spread above 15 %): the figures read low; compare figures measured at the "
                  "same host load (docs/speed.md)")

        # ---- penetration-like run ----
        mv = run_bench(runner, bench, a.packing, "moving", a.steps, a.period)
        mv["round"] = 0
        runs.append(mv)
        m = mv["moving"]
        share = m["rebuild_share"]
        print()
        print("moving: rebuilds %d in %d steps (%.1f steps per rebuild; cell strain rate %.4g 1/s, plane strain to "
              "%.2f %%), %.1f ms per rebuild, %.3f ms per step; rebuild share %.1f %% of the step; target <= %.0f %%: %s" % (
                  int(m["rebuilds"]), a.steps, m["steps_per_rebuild"], m["strain_rate"], 100 * m["strain_x"],
                  m["ms_per_rebuild"], mv["wall"] / a.steps * 1e3, 100 * share, 100 * TARGET_REBUILD_SHARE,
                  "met" if share <= TARGET_REBUILD_SHARE else "NOT met"))
        print("  moving: %.3e particle-steps/s per core, peak RSS %s MiB, active contacts at the end %d (held: %d)" % (
            mv["per_core"], fmt(mv["rss"], ".1f"), int(mv["phases"]["active"]), active))
        if lmp:
            mname = write_lammps(tmp, a.packing, inf["dt"], inf["skin"], a.steps, erate=m["strain_rate"])
            lm = run_lammps(runner, lmp, tmp, mname, n, a.steps)
            lm["code"] = "lammps_moving"
            lm["round"] = 0
            runs.append(lm)
            nb = lm["sections"].get("Neigh", 0.0)
            print("  LAMMPS, same strain rate (fix deform, remap x): %d builds, Neigh %.1f %% of the loop, "
                  "%.1f ms per build, %.3f ms per step, %.3e particle-steps/s per core, peak RSS %s MiB" % (
                      lm["rebuilds"], 100 * nb / lm["wall"], 1e3 * nb / max(lm["rebuilds"], 1),
                      lm["wall"] / a.steps * 1e3, lm["per_core"], fmt(lm["rss"], ".1f")))

        if a.bench_csv:
            with open(a.bench_csv, "w") as f:
                f.write(",".join(CSV_COLS) + "\n")
                for x in runs:
                    if x.get("raw"):
                        f.write(x["raw"] + "\n")
            print("bench_dem csv: " + a.bench_csv)
        if a.csv:
            with open(a.csv, "w", newline="") as f:
                w = csv.writer(f)
                f.write("# vs_lammps.py: %s; ISA %s; clock %.3f GHz (%s); triad %.2f GB/s at %.0f B, %.2f GB/s at "
                        "DRAM size\n" % (ci["model"], ci["isa"], ghz, gsrc, hw["triad_ws_gbs"],
                                          inf["working_set_bytes"], hw["triad_dram_gbs"]))
                w.writerow(["round", "code", "steps", "wall_s", "cpu_s", "particle_steps_per_s_per_core",
                            "particle_steps_per_s_wall", "ratio_to_lammps", "peak_rss_mib", "kernel_isa",
                            "rebuilds", "pair_s", "rebuild_s", "motion_s", "pair_ns_per_active_contact"])
                for x in runs:
                    ph = x.get("phases") or {}
                    sec = x.get("sections") or {}
                    w.writerow([x["round"], x["code"], x["steps"], "%.4f" % x["wall"], "%.4f" % x["cpu"],
                                "%.4e" % x["per_core"], "%.4e" % x["wall_rate"],
                                "%.3f" % x["ratio"] if "ratio" in x else "",
                                "%.1f" % x["rss"] if x["rss"] else "", x["kernel"], x["rebuilds"],
                                "%.4f" % ph.get("pair", sec.get("Pair", 0.0)),
                                "%.4f" % ph.get("rebuild", sec.get("Neigh", 0.0)),
                                "%.4f" % ph.get("motion", sec.get("Modify", 0.0)),
                                "%.2f" % x["ns_contact"] if "ns_contact" in x else ""])
            print("csv: " + a.csv)
    return 0


if __name__ == "__main__":
    sys.exit(main())

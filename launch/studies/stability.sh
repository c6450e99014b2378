#!/usr/bin/env bash
# Stability suite at full size: the hard cases of tests/stability on a paper scene, with a table.
#
# Usage: launch/study stability [--scene FILE] [--only "g200 g1000 ..."] [--runs-root DIR] [--table STUDY_DIR]
#   --scene FILE     base scene (default scenes/paper_100g_sbm.toml: 38075 balls, ~10 min per run here)
#   --only LIST      run only these cases (default: all; base runs first when a dt case is asked for)
#   --runs-root DIR  where the study folder goes (default ./runs; env DEMFDM_RUNS_ROOT)
#   --table DIR      do not run anything: rebuild the table of an existing study folder
# Cases (docs/stability.md): base, g200, g1000, soft_continuum (FDM young / 100), stiff_continuum
# (x 100), fast_footing (speed_factor 10), bond_cascade (soft bonds 100 x weaker), undamped
# (dem.damping 0, depth scaling off), dt_09 (dem.dt_fixed = 0.9 x the base run's smallest
# critical step), dt_above (3 x its largest: must be refused), dt_reduce (same, reduced), escape
# (top ball kicked at 200 m/s: must stop naming it).
# Writes DIR/studies/<date>-stability/<case>/ (run folders) and table.csv + table.md.
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
scene="$root/scenes/paper_100g_sbm.toml"
all="base g200 g1000 soft_continuum stiff_continuum fast_footing bond_cascade undamped dt_09 dt_above dt_reduce escape"
only="$all"; study=""
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) scene="$2"; shift ;;
    --only) only="$2"; shift ;;
    --runs-root) runs_root="$2"; shift ;;
    --table) study="$2"; shift ;;
    -h|--help) sed -n '3,15p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "stability study: unknown option '$1' (see launch/study stability --help)" >&2; exit 2 ;;
  esac
  shift
done
[ -f "$scene" ] || { echo "stability study: no scene $scene" >&2; exit 2; }

# Scene variant of a case: the base scene with the case's edits (first match of each).
variant() {
  /usr/bin/python3 - "$scene" "$1" "${2:-}" <<'PY'
import sys, re
text, case, crit = open(sys.argv[1]).read(), sys.argv[2], sys.argv[3]
def sub(pattern, repl):
    global text
    new, n = re.subn(pattern, repl, text, count=1, flags=re.M)
    if n != 1:
        sys.exit(f"stability study: case {case}: the scene has no line matching {pattern!r}")
    text = new
lo, hi = (float(x) for x in crit.split(":")) if crit else (0.0, 0.0)
edits = {
    "base": [],
    "g200": [(r"^level = .*$", "level = 200")],
    "g1000": [(r"^level = .*$", "level = 1000")],
    "soft_continuum": [(r"^young = ([0-9.e+-]+)$", lambda m: f"young = {float(m.group(1)) / 100:g}")],
    "stiff_continuum": [(r"^young = ([0-9.e+-]+)$", lambda m: f"young = {float(m.group(1)) * 100:g}")],
    "fast_footing": [(r"^mean_stress = (.*)$", r"mean_stress = \1\nspeed_factor = 10")],
    "bond_cascade": [(r"^\[dem.ball_ball\]$", "[dem.ball_ball]\nsb_ten = 4.5e3\nsb_coh = 4.5e3")
                     if re.search(r"^\[dem.ball_ball\]$", text, re.M) else
                     (r"^\[dem.specimen\]$", "[dem.ball_ball]\nsb_ten = 4.5e3\nsb_coh = 4.5e3\n\n[dem.specimen]")],
    "undamped": [(r"^\[dem\]$", "[dem]\ndamping = 0.0"), (r"^\[dem.specimen\]$", "[dem.specimen]\ndepth_scaling = \"none\"")],
    "dt_09": [(r"^\[dem\]$", f"[dem]\ndt_fixed = {0.9 * lo:.6e}")],
    "dt_above": [(r"^\[dem\]$", f"[dem]\ndt_fixed = {3 * hi:.6e}")],
    "dt_reduce": [(r"^\[dem\]$", f"[dem]\ndt_fixed = {3 * hi:.6e}\ndt_above_critical = \"reduce\"")],
    "escape": [(r"^\[dem\]$", "[dem]\nkick = [0.0, 0.0, 200.0]")],
}
if case not in edits:
    sys.exit(f"stability study: unknown case {case}")
for p, r in edits[case]:
    sub(p, r)
sys.stdout.write(text)
PY
}

# Smallest and largest DEM critical step of a finished run (history columns dem.dt_critical_s).
critical_range() {
  /usr/bin/python3 - "$1" <<'PY'
import csv, glob, math, sys
vals = []
for f in glob.glob(sys.argv[1] + "/history_*.csv"):
    for row in csv.DictReader(open(f)):
        v = float(row.get("dem.dt_critical_s", "nan"))
        if math.isfinite(v) and v > 0:
            vals.append(v)
if not vals:
    sys.exit("stability study: the base run reports no dem.dt_critical_s")
print(f"{min(vals)!r}:{max(vals)!r}")
PY
}

if [ -z "$study" ]; then
  study="$runs_root/studies/$(date +%Y%m%d-%H%M%S)-stability"
  mkdir -p "$study"
  echo "stability study: folder $study (base scene $scene)" >&2
  needs_base=0
  for c in $only; do case "$c" in dt_*) needs_base=1 ;; esac; done
  order="$only"
  if [ $needs_base = 1 ] && ! echo " $only " | grep -q " base "; then order="base $only"; fi
  crit=""
  for c in $order; do
    case "$c" in dt_*) [ -n "$crit" ] || crit=$(critical_range "$study/base") ;; esac
    variant "$c" "$crit" > "$study/$c.toml"
    t0=$(date +%s.%N)
    code=0
    "$root/launch/run" "$study/$c.toml" --no-build --run-dir "$study/$c" >"$study/$c.log" 2>&1 || code=$?
    t1=$(date +%s.%N)
    mkdir -p "$study/$c"
    echo "$code" > "$study/$c/exit_code.txt"
    /usr/bin/python3 -c "print(f'{$t1 - $t0:.1f}')" > "$study/$c/run_wall_s.txt"
    echo "stability study: $c exit $code in $(cat "$study/$c/run_wall_s.txt") s" >&2
  done
fi
[ -d "$study" ] || { echo "stability study: no folder $study" >&2; exit 2; }

# One row per case: exit code, wall time, guard report, largest kinetic energies, interface
# imbalance, largest dt / critical dt, energy balance errors and broken bonds (dem.log).
/usr/bin/python3 - "$study" <<'PY'
import csv, glob, math, os, re, sys
study = sys.argv[1]
rows = []
for d in sorted(p for p in glob.glob(study + "/*") if os.path.isdir(p) and os.path.exists(p + "/exit_code.txt")):
    case = os.path.basename(d)
    r = {"case": case, "exit_code": open(d + "/exit_code.txt").read().strip(),
         "wall_s": open(d + "/run_wall_s.txt").read().strip()}
    blow = sorted(glob.glob(d + "/blowup_*.txt"))
    r["guard"] = "clean" if not blow else re.sub(r"\s+", " ", open(blow[0]).read().split("cause: ", 1)[-1].split("\n")[0])[:160]
    def colmax(path, col):
        m = -math.inf
        if os.path.exists(path):
            for row in csv.DictReader(open(path)):
                v = float(row.get(col, "nan"))
                if math.isfinite(v):
                    m = max(m, v)
        return m
    r["ke_dem_max_J"] = colmax(d + "/dem_history.csv", "kinetic_J")
    r["ke_fdm_max_J"] = colmax(d + "/fdm_history.csv", "kinetic_J")
    imb, ratio = -math.inf, -math.inf
    for f in glob.glob(d + "/history_*.csv"):
        for row in csv.DictReader(open(f)):
            v = float(row.get("continuum.iface_imbalance", "nan"))
            if math.isfinite(v):
                imb = max(imb, v)
            for n in ("dem", "continuum"):
                a, b = float(row.get(n + ".dt_s", "nan")), float(row.get(n + ".dt_critical_s", "nan"))
                if math.isfinite(a) and math.isfinite(b) and b > 0:
                    ratio = max(ratio, a / b)
    r["iface_imbalance_max"] = imb
    r["dt_over_critical_max"] = ratio
    log = open(d + "/dem.log").read() if os.path.exists(d + "/dem.log") else ""
    for stage in ("gravity", "penetrate"):
        m = re.findall(r"'%s' ends after step \d+; values:(.*)" % stage, log)
        vals = dict(kv.split("=", 1) for kv in m[-1].split()) if m else {}
        r["energy_error_" + stage] = vals.get("energy_balance_error", "")
        if stage == "penetrate":
            r["bonds_broken"] = (float(vals["bonds_broken_tension"]) + float(vals["bonds_broken_shear"])) if vals else ""
    err = ""
    if r["exit_code"] != "0" and os.path.exists(d + ".log"):
        m = re.search(r"run failed: (.*)", open(d + ".log").read())
        err = m.group(1)[:200] if m else ""
    r["error"] = err
    for k, v in r.items():
        if isinstance(v, float) and not math.isfinite(v):
            r[k] = ""  # no such column in this run (e.g. it stopped before any grant)
    rows.append(r)
if not rows:
    sys.exit("stability study: no finished cases in " + study)
keys = list(rows[0].keys())
with open(study + "/table.csv", "w", newline="") as f:
    w = csv.DictWriter(f, keys)
    w.writeheader()
    w.writerows(rows)
def fmt(v):
    return f"{v:.3g}" if isinstance(v, float) else str(v).replace("|", "/")
with open(study + "/table.md", "w") as f:
    f.write("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n")
    for r in rows:
        f.write("| " + " | ".join(fmt(r[k]) for k in keys) + " |\n")
print(open(study + "/table.md").read())
PY
echo "stability study: table in $study/table.csv and table.md" >&2

#!/usr/bin/env bash
# Stability suite at full size: the hard cases of tests/stability on a paper scene, with a table.
#
# Usage: launch/study stability [--scene FILE] [--only "g200 g1000 ..."] [--runs-root DIR] [--table STUDY_DIR]
#                               [--check]
#   --scene FILE     base scene (default scenes/paper_100g_sbm.toml: 38075 balls, ~10 min per run here)
#   --only LIST      run only these cases (default: all; base runs first when a dt case is asked for)
#   --runs-root DIR  where the study folder goes (default ./runs; env DEMFDM_RUNS_ROOT)
#   --table DIR      do not run anything: rebuild the table of an existing study folder
#   --check          list each case's launch/run command and check it with the coordinator; run
#                    nothing (the dt cases with a stand-in critical step of 1e-8 s: the study
#                    takes it from its base run)
# Cases (docs/stability.md): base, g200, g1000, soft_continuum (FDM young / 100), stiff_continuum
# (x 100), fast_footing (speed_factor 10), bond_cascade (soft bonds 100 x weaker), undamped
# (dem.damping 0, depth scaling off), dt_09 (dem.dt_fixed = 0.9 x the base run's smallest
# critical step), dt_above (3 x its largest: must be refused), dt_reduce (same, reduced), escape
# (top ball kicked at 200 m/s: must stop naming it). Each case is the base scene with overrides
# (launch/run --set; its run folder records the effective scene as scene.toml).
# Writes DIR/studies/<date>-stability/<case>/ (run folders) and table.csv + table.md.
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
scene="$root/scenes/paper_100g_sbm.toml"
all="base g200 g1000 soft_continuum stiff_continuum fast_footing bond_cascade undamped dt_09 dt_above dt_reduce escape"
only="$all"; study=""; check=0
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) scene="$2"; shift ;;
    --only) only="$2"; shift ;;
    --runs-root) runs_root="$2"; shift ;;
    --table) study="$2"; shift ;;
    --check) check=1 ;;
    -h|--help) sed -n '3,19p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "stability study: unknown option '$1' (see launch/study stability --help)" >&2; exit 2 ;;
  esac
  shift
done
[ -f "$scene" ] || { echo "stability study: no scene $scene" >&2; exit 2; }

# The overrides of a case, one per line (launch/run "$scene" --set each): the scene file itself is
# never edited. Values that scale the scene's own (the continuum's Young modulus) are read from its
# effective scene (every value in effect, defaults filled; launch/py/overrides.py).
case_sets() {
  /usr/bin/python3 - "$root/launch/py" "$scene" "$1" "${2:-}" <<'PY'
import sys, tomllib
sys.path.insert(0, sys.argv[1])
import overrides
scene, case, crit = sys.argv[2], sys.argv[3], sys.argv[4]
lo, hi = (float(x) for x in crit.split(":")) if crit else (0.0, 0.0)
def young(scale):
    mats = tomllib.loads(overrides.effective(scene)).get("continuum", {}).get("material", [])
    if not mats:
        sys.exit(f"stability study: case {case}: the scene has no [[continuum.material]]")
    return [f"continuum.material[0].young={scale(float(mats[0]['young'])):g}"]
def penetration_stage():
    # The stage that sets mean_stress in the scene file (else the first penetration stage).
    stages = overrides.scene_values(scene).get("stage", [])
    for pick in (lambda s: "mean_stress" in s, lambda s: s.get("action") == "penetrate"):
        for i, s in enumerate(stages):
            if pick(s):
                return "stage.%s" % s["name"] if s.get("name") else "stage[%d]" % i
    sys.exit(f"stability study: case {case}: the scene has no penetration stage")
cases = {
    "base": lambda: [],
    "g200": lambda: ["gravity.level=200"],
    "g1000": lambda: ["gravity.level=1000"],
    "soft_continuum": lambda: young(lambda e: e / 100),
    "stiff_continuum": lambda: young(lambda e: e * 100),
    "fast_footing": lambda: [penetration_stage() + ".speed_factor=10"],
    "bond_cascade": lambda: ["dem.ball_ball.softbond.ten=4.5e3", "dem.ball_ball.softbond.coh=4.5e3"],
    "undamped": lambda: ["dem.damping=0.0", 'dem.specimen.depth_scaling="none"'],
    "dt_09": lambda: [f"dem.dt_fixed={0.9 * lo:.6e}"],
    "dt_above": lambda: [f"dem.dt_fixed={3 * hi:.6e}"],
    "dt_reduce": lambda: [f"dem.dt_fixed={3 * hi:.6e}", 'dem.dt_above_critical="reduce"'],
    "escape": lambda: ["dem.kick=[0.0, 0.0, 200.0]"],
}
if case not in cases:
    sys.exit(f"stability study: unknown case {case}")
for s in cases[case]():
    print(s)
PY
}

# The launch/run --set arguments of a case (into the array set_args).
case_args() {
  local out s
  out="$(case_sets "$1" "${2:-}")" || exit 2
  set_args=()
  while IFS= read -r s; do [ -n "$s" ] && set_args+=("--set=$s"); done <<< "$out"
  return 0
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

if [ "$check" -eq 1 ]; then
  refused=0
  for c in $only; do
    case_args "$c" "1e-8:1e-8"
    shown=""
    for s in "${set_args[@]}"; do
      if [[ "$s" =~ ^[A-Za-z0-9._=/:+-]+$ ]]; then shown+=" $s"; else shown+=" '$s'"; fi
    done
    echo "$c: launch/run $scene$shown"
    "$root/launch/run" "$scene" --check --no-build "${set_args[@]}" > /dev/null || refused=$((refused + 1))
  done
  echo "stability study: $(echo $only | wc -w) case(s) checked by the coordinator, $refused refused" >&2
  [ "$refused" -eq 0 ] || exit 2
  exit 0
fi

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
    case_args "$c" "$crit"
    t0=$(date +%s.%N)
    code=0
    "$root/launch/run" "$scene" --no-build "${set_args[@]}" --run-dir "$study/$c" >"$study/$c.log" 2>&1 || code=$?
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

#!/usr/bin/env bash
# Convergence of the footing prediction (issue 12): rate, damping and DEM step, seed ensembles.
#
# Usage: launch/study converge [--parts "rate dt"] [--seeds N] [--jobs J] [--rate I] [--damping A]
#                              [--quick] [--runs-root DIR | --into STUDY_DIR] [--table STUDY_DIR]
#                              [--list | --check]
#   --parts P      rate: I = 1e-2, 3.3e-3, 1e-3, 3.3e-4 at penetration damping 0.7 and 0.1;
#                  dt: dem.dt_safety 0.8 / 0.4 / 0.2 at --rate and --damping (default "rate dt");
#                  damping: penetration damping 0.05 and 0 against 0.1 at --rate;
#                  box: the coupled model (DEM block 2 x 2 x 2 and 2 x 2 x 3 mm) against DEM
#                  everywhere in the same 4 x 4 x 4 mm box, upscaling 1.5, at --rate and --damping
#                  wide: the same under the paper scenes' footing (D_f = 1.2 mm, seven grains) at
#                  I = 7.5e-4 and --damping, 6 x 6 x 4 mm outer box: DEM everywhere (about 34,000
#                  balls) against DEM blocks of 2 x 2 x 2, 4 x 4 x 2 and 4 x 4 x 3 mm in the FDM
#   --seeds N      seeds 1..N of every variant (default 5); seed k is the same bonded block in
#                  every variant, so knobs are compared by paired differences
#   --jobs J       runs at once (default 1; each run is a DEM and a continuum process)
#   --rate I       inertial number of the dt part (default 1e-3)
#   --damping A    penetration damping of the dt part (default 0.1, the protocol's)
#   --quick        penetration to 0.05 D_f (development)
#   --no-branch    run every variant from scratch (default: variants that differ only in the
#                  penetration branch from the first run's checkpoint after gravity)
#   --into DIR     extend an existing study folder (finished seeds are kept: a study resumes)
#   --table DIR    run nothing: rebuild the tables and figures of a study folder
#   --list         run nothing: the variants of --parts with their launch/run commands (a scene
#                  and --set overrides; seed k adds run.seed=k)
#   --check        the same, and every variant and seed checked by the coordinator
# Writes DIR/studies/<date>-converge/: one folder per variant with seed-<k>/ run folders (each
# records its effective scene, scenes/accuracy_footing.toml or accuracy_footing_box.toml with the
# variant's overrides, as scene.toml), convergence_tables.md, converge_seeds.csv,
# converge_rate.png, converge_dt.png (and converge_box.png, converge_damping.png, converge_wide.png
# for those parts).
# Cost on this 2-core machine (2026-12-02, base scene scenes/accuracy_footing.toml, 2,856 balls):
# 10 / 40 / 90 / 270 s per run at I = 1e-2 / 3.3e-3 / 1e-3 / 3.3e-4. Reading: docs/convergence.md.
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
args=(); plan_args=(); study=""; into=""; table=""; list=""
while [ $# -gt 0 ]; do
  case "$1" in
    --parts) read -r -a p <<< "$2"; args+=(--parts "${p[@]}"); plan_args+=(--parts "${p[@]}"); shift ;;
    --seeds|--rate|--damping) args+=("$1" "$2"); plan_args+=("$1" "$2"); shift ;;
    --jobs) args+=("$1" "$2"); shift ;;
    --quick) args+=(--quick); plan_args+=(--quick) ;;
    --list) list=list ;;
    --check) list=check ;;
    --no-branch) args+=(--no-branch) ;;
    --runs-root) runs_root="$2"; shift ;;
    --into) into="$2"; shift ;;
    --table) table="$2"; shift ;;
    -h|--help) sed -n '3,30p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "converge study: unknown option '$1' (see launch/study converge --help)" >&2; exit 2 ;;
  esac
  shift
done
if [ -n "$list" ]; then
  [ "$list" = list ] || plan_args+=(--check)
  exec /usr/bin/python3 "$root/launch/py/converge_study.py" list "${plan_args[@]}"
fi
if [ -n "$table" ]; then
  [ -f "$table/plan.json" ] || { echo "converge study: no study folder $table (plan.json missing)" >&2; exit 2; }
  exec /usr/bin/python3 "$root/launch/py/converge_study.py" table "$table"
fi
study="${into:-$runs_root/studies/$(date +%Y%m%d-%H%M%S)-converge}"
[ -z "$into" ] || [ -f "$into/plan.json" ] || { echo "converge study: --into $into: not a study folder" >&2; exit 2; }
echo "converge study: folder $study" >&2
status=0
/usr/bin/python3 "$root/launch/py/converge_study.py" run "$study" "${args[@]}" || status=$?
[ "$status" -ne 2 ] || exit 2  # a run the coordinator refuses: nothing ran
/usr/bin/python3 "$root/launch/py/converge_study.py" table "$study" > /dev/null
echo "converge study: tables and figures in $study (convergence_tables.md)" >&2
exit "$status"

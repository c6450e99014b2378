#!/usr/bin/env bash
# Accuracy-cost study (issue 7): wall time against error for each knob that trades accuracy for time.
#
# Usage: launch/study accuracy [--quick] [--seeds N] [--only "KNOB ..."] [--runs-root DIR | --into STUDY_DIR]
#                             [--table STUDY_DIR] [--list] [--check]
#   --quick          development mode (83 s at load 3-6): footing at scale 2 to 0.05 D_f, UCS to
#                    strain 0.002, two settings of the cheap knobs, one seed
#   --seeds N        footing settings run with generator seeds 1..N and are measured on the
#                    seed-mean curve, with its standard error (default 3; --quick: 1)
#   --only KNOBS     run only these knobs (scale interval scheme dem_only dt_safety zone_size continuum
#                    damping seed ucs_scale; seed only with --seeds 1)
#   --runs-root DIR  where the study folder goes (default ./runs; env DEMFDM_RUNS_ROOT)
#   --into DIR       extend an existing study folder: run only the scenes it does not have yet
#   --table DIR      run nothing: rebuild the table and figure of an existing study folder
#   --list           print the knobs and their settings
#   --check          run nothing: list the distinct runs with their launch/run commands (a scene
#                    and --set overrides), each checked by the coordinator (with --into: which ran)
#   --no-branch      run every scene from scratch (default: a scene that shares its first stages
#                    with a finished one starts from its saved state, launch/run --from)
# Writes DIR/studies/<date>-accuracy/ with one run folder per distinct run (a scene,
# scenes/accuracy_footing.toml, accuracy_footing_box.toml or ucs_sbm_s1.5.toml, with launch/run
# --set overrides; each run folder records its effective scene as scene.toml), accuracy_table.csv,
# accuracy_table.md and accuracy_pareto.png. Full study with 3 seeds: about 20 min on this 2-core
# machine with the UCS runs at scales 1-2 (the scale-1 UCS run alone takes about 14 min).
# Knobs, metrics and a reading of a full run: docs/accuracy-study.md.
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
args=(); study=""; into=""; seeds=3; quick=0; check=0
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) args+=(--quick); quick=1 ;;
    --seeds) [ $# -ge 2 ] || { echo "accuracy study: --seeds needs a number" >&2; exit 2; }
             seeds="$2"; shift ;;
    --only) [ $# -ge 2 ] || { echo "accuracy study: --only needs a knob list" >&2; exit 2; }
            read -r -a k <<< "$2"; args+=(--only "${k[@]}"); shift ;;
    --runs-root) runs_root="$2"; shift ;;
    --table) study="$2"; shift ;;
    --into) into="$2"; shift ;;
    --no-branch) args+=(--no-branch) ;;
    --list) exec /usr/bin/python3 "$root/launch/py/accuracy_study.py" list ;;
    --check) check=1 ;;
    -h|--help) sed -n '3,25p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "accuracy study: unknown option '$1' (see launch/study accuracy --help)" >&2; exit 2 ;;
  esac
  shift
done
if [ -n "$study" ]; then
  [ -f "$study/plan.json" ] || { echo "accuracy study: no study folder $study (plan.json missing)" >&2; exit 2; }
  exec /usr/bin/python3 "$root/launch/py/accuracy_study.py" table "$study"
fi
study="${into:-$runs_root/studies/$(date +%Y%m%d-%H%M%S)-accuracy}"
[ -z "$into" ] || [ -f "$into/plan.json" ] || { echo "accuracy study: --into $into: not a study folder (no plan.json)" >&2; exit 2; }
case "$seeds" in ''|*[!0-9]*|0) echo "accuracy study: --seeds needs a positive integer, found '$seeds'" >&2; exit 2 ;; esac
[ "$quick" = 0 ] || [ "$seeds" != 3 ] || seeds=1
args+=(--seeds "$seeds")
if [ "$check" = 1 ]; then
  exec /usr/bin/python3 "$root/launch/py/accuracy_study.py" plan ${into:+"$into"} "${args[@]}"
fi
echo "accuracy study: folder $study" >&2
/usr/bin/python3 "$root/launch/py/accuracy_study.py" run "$study" "${args[@]}"
echo "accuracy study: table and figure in $study" >&2

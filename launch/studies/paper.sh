#!/usr/bin/env bash
# The paper's coupled footing study (Figs. 3-7): SBM at 1, 50, 100, 200 g and PBM at 100 g, upscaling 1.5.
#
# Usage: launch/study paper [--only "100g_sbm 100g_pbm ..."] [--seeds N [--jobs J]] [--runs-root DIR]
#                           [--figures STUDY_DIR] [--check]
#   --only LIST      run only these scenes (names after scenes/paper_, default: all five)
#   --seeds N        each scene as a seed ensemble (seeds 1..N, launch/py/ensemble.py; J runs at once):
#                    ensemble tables per scene and the paper's findings with confidence intervals
#                    (findings.md, launch/py/paper_findings.py); the figures use seed 1
#   --runs-root DIR  where the study folder goes (default ./runs; env DEMFDM_RUNS_ROOT)
#   --figures DIR    do not run anything: redraw the figures of an existing study folder
#   --check          run nothing: list the runs (each scene as it is; with --seeds, seed k with
#                    --set run.seed=k) and check each with the coordinator
# Writes DIR/studies/<date>-paper/ with one run folder per scene (scenes/paper_*.toml, each
# about 10 minutes on this 2-core machine), run_wall_s.txt in each, then fig3..fig7 as CSV and PNG
# and summary.csv (peak load, initial stiffness, bond counts per run) via
# launch/py/paper_figures.py. Procedure and decisions: docs/paper-study.md.
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
all="100g_sbm 100g_pbm 1g_sbm 50g_sbm 200g_sbm"
only="$all"; study=""; seeds=""; jobs=1; check=0
while [ $# -gt 0 ]; do
  case "$1" in
    --only) only="$2"; shift ;;
    --runs-root) runs_root="$2"; shift ;;
    --figures) study="$2"; shift ;;
    --seeds) seeds="$2"; shift ;;
    --jobs) jobs="$2"; shift ;;
    --check) check=1 ;;
    -h|--help) sed -n '3,17p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "paper study: unknown option '$1' (see launch/study paper --help)" >&2; exit 2 ;;
  esac
  shift
done
for n in $only; do
  [ -f "$root/scenes/paper_$n.toml" ] || { echo "paper study: no scene scenes/paper_$n.toml" >&2; exit 2; }
done
if [ "$check" -eq 1 ]; then
  refused=0
  for n in $only; do
    if [ -n "$seeds" ]; then
      echo "launch/run scenes/paper_$n.toml --seeds $seeds (seed k: --set run.seed=k --set output.traffic_log=false)"
      /usr/bin/python3 "$root/launch/py/ensemble.py" run "${TMPDIR:-/tmp}/demfdm-paper-check-$$/$n" \
        --scene "$root/scenes/paper_$n.toml" --seeds "$seeds" --check || refused=$((refused + 1))
    else
      echo "launch/run scenes/paper_$n.toml"
      "$root/launch/run" "$root/scenes/paper_$n.toml" --check --no-build > /dev/null || refused=$((refused + 1))
    fi
  done
  echo "paper study: $(echo $only | wc -w) scene(s) checked by the coordinator, $refused refused" >&2
  [ "$refused" -eq 0 ] || exit 2
  exit 0
fi
if [ -z "$study" ]; then
  study="$runs_root/studies/$(date +%Y%m%d-%H%M%S)-paper"
  mkdir -p "$study"
  echo "paper study: folder $study" >&2
  for n in $only; do
    if [ -n "$seeds" ]; then
      /usr/bin/python3 "$root/launch/py/ensemble.py" run "$study/$n" --scene "$root/scenes/paper_$n.toml" \
        --seeds "$seeds" --jobs "$jobs" || { echo "paper study: ensemble $n failed (see $study/$n)" >&2; exit 3; }
      /usr/bin/python3 "$root/launch/py/ensemble.py" table "$study/$n" > /dev/null
      echo "paper study: $n ensemble done ($study/$n/ensemble.md)" >&2
      continue
    fi
    t0=$(date +%s.%N)
    "$root/launch/run" "$root/scenes/paper_$n.toml" --no-build --run-dir "$study/$n" >"$study/$n.log" 2>&1 \
      || { echo "paper study: run $n failed, see $study/$n.log" >&2; exit 3; }
    t1=$(date +%s.%N)
    /usr/bin/python3 -c "print(f'{$t1 - $t0:.1f}')" > "$study/$n/run_wall_s.txt"
    echo "paper study: $n done in $(cat "$study/$n/run_wall_s.txt") s" >&2
  done
fi
[ -d "$study" ] || { echo "paper study: no folder $study" >&2; exit 2; }
# Finished runs only (a run folder gets summary.txt when its coordinator ends); in an ensemble
# study the figures use seed 1 of each scene.
run_of() { if [ -d "$study/$1/seed-1" ]; then echo "$study/$1/seed-1"; else echo "$study/$1"; fi; }
have() { local d; d="$(run_of "$1")"; [ -f "$d/summary.txt" ] && ! grep -q '^FAILED' "$d/summary.txt"; }
args=()
for n in $all; do have "$n" && args+=(--run "$n=$(run_of "$n")"); done
[ ${#args[@]} -gt 0 ] || { echo "paper study: no finished runs in $study" >&2; exit 3; }
have 100g_sbm && args+=(--fig3 100g_sbm --fig7 100g_sbm)
have 100g_sbm && have 100g_pbm && args+=(--fig4 100g_sbm 100g_pbm)
g=(); for l in 1 50 100 200; do have "${l}g_sbm" && g+=("${l}g_sbm:$l"); done
[ ${#g[@]} -gt 0 ] && args+=(--glevels "${g[@]}")
d_f=$(sed -n 's/^diameter = //p' "$root/scenes/paper_100g_sbm.toml" | head -1)
/usr/bin/python3 "$root/launch/py/paper_figures.py" "$study/figures" --d-f "$d_f" "${args[@]}"
if ls -d "$study"/*/seed-1 > /dev/null 2>&1; then
  /usr/bin/python3 "$root/launch/py/paper_findings.py" "$study" > /dev/null
  echo "paper study: findings with confidence intervals in $study/findings.md" >&2
fi
# Stage and run wall times, bus-wait shares, particles and zones: from each run's summary.txt.
for n in $all; do
  d="$(run_of "$n")"
  [ -f "$d/summary.txt" ] || continue
  echo "== $n ($(cat "$d/run_wall_s.txt" 2>/dev/null || echo ?) s)"
  sed -n '/^stages:/,/^total:/p' "$d/summary.txt"
done > "$study/figures/timings.txt"
echo "paper study: figures in $study/figures" >&2

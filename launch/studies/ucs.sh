#!/usr/bin/env bash
# The paper's UCS scale-effect study (Table 1, Fig. 1): soft bond at scales 1, 1.3, 1.5 and parallel bond at scale 1.
#
# Usage: launch/study ucs [--quick] [--seeds N] [--scales "1.5 1.3 1"] [--no-pbm] [--runs-root DIR] [--check]
#   --quick      scale 1.5, soft bond, one seed (a CI-sized check, a few minutes)
#   --seeds N    seeds 1..N per scene (default 1)
#   --scales S   soft-bond scales to run (default "1.5 1.3 1"; scale 1 has 25,751 balls)
#   --no-pbm     skip the parallel-bond run at scale 1
#   --check      list the runs and check each with the coordinator (launch/run --check); run nothing
# Writes a study folder DIR/studies/<date>-ucs/ with one run folder per scene and seed, then
# ucs_table.csv, ucs_table.md (N_p, n, Z beside Table 1; E50 and UCS per scale) and
# ucs_stress_strain.png (like the paper's Fig. 1). Scenes: scenes/ucs_{sbm,pbm}_s*.toml; seed k of
# a scene runs it as it is with one override, launch/run SCENE --set run.seed=k (its run folder
# records the effective scene as scene.toml).
set -euo pipefail
root="${DEMFDM_ROOT:?run through launch/study}"
runs_root="${DEMFDM_RUNS_ROOT:-$PWD/runs}"
seeds=1; scales="1.5 1.3 1"; pbm=1; check=0
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) scales="1.5"; seeds=1; pbm=0 ;;
    --seeds) seeds="$2"; shift ;;
    --scales) scales="$2"; shift ;;
    --no-pbm) pbm=0 ;;
    --runs-root) runs_root="$2"; shift ;;
    --check) check=1 ;;
    -h|--help) sed -n '3,14p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "ucs study: unknown option '$1' (see launch/study ucs --help)" >&2; exit 2 ;;
  esac
  shift
done
[[ "$seeds" =~ ^[1-9][0-9]*$ ]] || { echo "ucs study: --seeds must be a positive integer, found '$seeds'" >&2; exit 2; }
scenes=()
for s in $scales; do
  f="$root/scenes/ucs_sbm_s$s.toml"
  [ -f "$f" ] || { echo "ucs study: no scene for scale '$s' ($f)" >&2; exit 2; }
  scenes+=("$f")
done
[ "$pbm" -eq 1 ] && scenes+=("$root/scenes/ucs_pbm_s1.toml")

if [ "$check" -eq 1 ]; then
  refused=0
  for f in "${scenes[@]}"; do
    for ((k = 1; k <= seeds; k++)); do
      echo "launch/run ${f#"$root"/} --set run.seed=$k"
      "$root/launch/run" "$f" --check --no-build --set "run.seed=$k" > /dev/null || refused=$((refused + 1))
    done
  done
  echo "ucs study: $(( ${#scenes[@]} * seeds )) run(s) checked by the coordinator, $refused refused" >&2
  [ "$refused" -eq 0 ] || exit 2
  exit 0
fi

study="$runs_root/studies/$(date +%Y%m%d-%H%M%S)-ucs"
mkdir -p "$study"
echo "ucs study: folder $study" >&2
failed=0
for f in "${scenes[@]}"; do
  name="$(basename "$f" .toml)"
  for ((k = 1; k <= seeds; k++)); do
    t0=$(date +%s.%N)
    if ! "$root/launch/run" "$f" --no-build --set "run.seed=$k" --run-dir "$study/$name-seed$k" \
        >"$study/$name-seed$k.log" 2>&1; then
      echo "ucs study: run $name seed $k failed, see $study/$name-seed$k.log (continuing)" >&2
      failed=$((failed + 1)); continue
    fi
    t1=$(date +%s.%N)
    python3 -c "print(f'{$t1 - $t0:.1f}')" > "$study/$name-seed$k/run_wall_s.txt"
    echo "ucs study: $name seed $k done in $(cat "$study/$name-seed$k/run_wall_s.txt") s" >&2
  done
done
/usr/bin/python3 "$root/launch/py/ucs_study.py" "$study"
[ "$failed" -eq 0 ] || { echo "ucs study: $failed run(s) failed" >&2; exit 3; }

#!/usr/bin/env bash
# A dead rank is named within 5 s (issue 17 item 3; tests/dist/dead_rank.cpp): the last of 2
# ranks kills itself with SIGKILL while the ranks step; mpirun must end the job with a non-zero
# code, name the rank and its signal, and do so within 5 s of the kill.
# Usage: dead_rank.sh MPIEXEC DEAD_RANK_EXECUTABLE
set -uo pipefail
mpiexec="$1"
exe="$2"
out="$(mktemp)"
trap 'rm -f "$out"' EXIT
timeout 120 "$mpiexec" -np 2 --oversubscribe "$exe" > "$out" 2>&1
rc=$?
end=$(date +%s.%N)
cat "$out"
killed=$(sed -n 's/^dead_rank: rank [0-9]* kills itself at \([0-9.]*\)$/\1/p' "$out")
if [ -z "$killed" ]; then echo "FAIL: the rank did not reach its kill"; exit 1; fi
if [ "$rc" -eq 0 ] || [ "$rc" -eq 124 ]; then echo "FAIL: mpirun exited with $rc (0: not noticed; 124: hung)"; exit 1; fi
if ! grep -q "process rank 1 .*exited on signal 9" "$out"; then echo "FAIL: the dead rank is not named"; exit 1; fi
elapsed=$(awk -v a="$killed" -v b="$end" 'BEGIN { printf "%.2f", b - a }')
echo "dead rank named, mpirun exit code $rc, ${elapsed} s after the kill"
awk -v e="$elapsed" 'BEGIN { exit !(e < 5.0) }' || { echo "FAIL: more than 5 s"; exit 1; }

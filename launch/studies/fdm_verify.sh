#!/usr/bin/env bash
# FDM verification scenes (no DEM node) run through launch/run, compared with closed forms.
# Writes <study>/fdm_verification.md (table of errors). Usage: launch/study fdm_verify [--out DIR]
set -euo pipefail
out="${PWD}/runs/study-fdm-verify-$(date +%Y%m%d-%H%M%S)"
[ "${1:-}" = "--out" ] && out="$2"
if [ -e "$out" ] && [ -n "$(ls -A "$out" 2>/dev/null)" ]; then
  echo "fdm_verify: '$out' exists and is not empty; an earlier study is never overwritten" >&2; exit 2
fi
mkdir -p "$out"
for s in fdm_column fdm_punch fdm_wave fdm_triaxial; do
  "$DEMFDM_ROOT/launch/run" "$DEMFDM_ROOT/scenes/$s.toml" --no-build --run-dir "$out/$s" > "$out/$s.out" 2>&1 || {
    echo "fdm_verify: $s failed; see $out/$s.out" >&2; exit 1; }
done
/usr/bin/python3 "$DEMFDM_ROOT/launch/py/fdm_verify.py" "$out"

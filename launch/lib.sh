# Shared by launch/run, launch/test, launch/study: install missing Debian packages, build.
# Sourced, not executed.
DEMFDM_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEMFDM_BUILD="${DEMFDM_BUILD:-$DEMFDM_ROOT/build}"

demfdm_missing_packages() {
  local pkg missing=()
  while read -r pkg; do
    pkg="${pkg%%#*}"; pkg="${pkg// /}"
    [ -z "$pkg" ] && continue
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done < "$DEMFDM_ROOT/launch/packages.txt"
  echo "${missing[@]:-}"
}

demfdm_ensure_packages() {
  local missing
  missing="$(demfdm_missing_packages)"
  [ -z "$missing" ] && return 0
  if [ "$(id -u)" -eq 0 ]; then
    echo "demfdm: installing missing Debian packages: $missing" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >&2 || { echo "demfdm: apt-get update failed" >&2; return 1; }
    # shellcheck disable=SC2086
    apt-get install -y -qq --no-install-recommends $missing >&2 || {
      echo "demfdm: apt-get install failed for: $missing" >&2; return 1; }
  else
    echo "demfdm: missing Debian packages. Install them with:" >&2
    echo "  sudo apt-get install -y $missing" >&2
    return 1
  fi
}

demfdm_build() {
  local jobs; jobs="$(nproc 2>/dev/null || echo 2)"
  if [ ! -f "$DEMFDM_BUILD/CMakeCache.txt" ]; then
    cmake -S "$DEMFDM_ROOT" -B "$DEMFDM_BUILD" -DCMAKE_BUILD_TYPE=Release >&2 || return 1
  fi
  cmake --build "$DEMFDM_BUILD" -j "$jobs" >&2 || return 1
}

# Run a command in a private network namespace when root, so that no multicast leaves
# the machine: only 'lo', brought up with multicast and a 224.0.0.0/4 route.
demfdm_netns_prefix() {
  if [ "$(id -u)" -eq 0 ] && [ -z "${DEMFDM_IN_NETNS:-}" ] && command -v unshare >/dev/null; then
    echo "unshare -n --"
  fi
}
demfdm_netns_setup() {
  # Called inside the namespace.
  ip link set lo up 2>/dev/null || true
  ip link set lo multicast on 2>/dev/null || true
  ip route add 224.0.0.0/4 dev lo 2>/dev/null || true
}

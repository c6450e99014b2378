#!/usr/bin/env bash
# The DEM on ranks across two "hosts" (issue 17 item 4): two network namespaces, each with its
# own host name, joined by a veth pair (10.77.0.1 and 10.77.0.2). mpirun in host A starts its
# daemon in host B through ns_agent.sh (as it would through ssh); the ranks talk MPI over TCP on
# the veth pair only (no shared memory). Checks: one rank runs on each host, and the rank-count
# cases give the bits of one World. Nothing leaves the namespaces.
# Usage: two_hosts.sh DIST_TESTS   (exit 77 = skipped: needs root, unshare, nsenter and ip)
set -euo pipefail
tests="$1"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
. "$here/two_hosts_lib.sh"
if [ -z "${TWO_HOSTS_INNER:-}" ]; then
  two_hosts_check
  exec unshare -n -u -- env TWO_HOSTS_INNER=1 "$0" "$@"
fi
# host A: this namespace; host B: a holder in its own
work="$(mktemp -d)"
trap 'kill ${TWO_HOSTS_B_PID:-} 2>/dev/null || true; rm -rf "$work"' EXIT
two_hosts_make 10.77.0 || exit $?
printf '10.77.0.1 slots=1\n10.77.0.2 slots=1\n' > "$work/hosts"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1
run() {
  mpirun -np 2 --map-by node --hostfile "$work/hosts" --mca plm_rsh_agent "$here/ns_agent.sh" \
    --mca btl self,tcp --mca btl_tcp_if_include 10.77.0.0/24 --mca oob_tcp_if_include 10.77.0.0/24 "$@"
}
names="$(run hostname | sort | tr '\n' ' ')"
echo "ranks on: $names"
if [ "$names" != "hosta hostb " ]; then
  echo "FAIL: expected one rank on hosta and one on hostb, found: $names"
  exit 1
fi
run "$tests" --gtest_filter='Dist.LinearFreeSameBits:DistWalls.LinearFloorCutAlongXSameBits'

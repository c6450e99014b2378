#!/usr/bin/env bash
# The coupled run with its DEM on two "hosts" (issue 17 item 4): two network namespaces, each
# with its own host name, joined by a veth pair (10.77.1.1 = hosta, 10.77.1.2 = hostb), multicast
# routed over it. The coordinator and the continuum run in host A; the DEM runs on 2 MPI ranks,
# rank 0 (the one on the bus) in host B and rank 1 in host A, MPI over TCP on the veth pair. The
# bus therefore crosses the pair both ways (LCM multicast, ttl=1). Checks: the coordinator hears
# the DEM from hostb, one rank runs on each host, and the run's histories are the bytes of the
# same scene run by launch/run on one machine and one process. Nothing leaves the namespaces.
# Usage: node_two_hosts.sh SOURCE_DIR BUILD_DIR   (exit 77 = skipped: needs root, unshare, nsenter, ip)
set -euo pipefail
src="$1"
build="$2"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
. "$here/two_hosts_lib.sh"
bin="$build/bin"
if [ -z "${TWO_HOSTS_INNER:-}" ]; then
  two_hosts_check
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
  # The reference: the scene through launch/run, one process.
  DEMFDM_BUILD="$build" "$src/launch/run" "$src/scenes/footing_small.toml" --no-build --run-dir "$work/one" \
    --set output.traffic_log=false > "$work/one.out" 2>&1 || { cat "$work/one.out"; echo "FAIL: the reference run"; exit 1; }
  TWO_HOSTS_INNER=1 TWO_HOSTS_WORK="$work" unshare -n -u -- "$0" "$@"
  exit $?
fi
work="$TWO_HOSTS_WORK"
# host A: this namespace; host B: a holder in its own; multicast routed over the pair
pids=()
cleanup() { for p in "${pids[@]}" ${TWO_HOSTS_B_PID:-}; do kill -KILL "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
two_hosts_make 10.77.1 || exit $?
bpid="$TWO_HOSTS_B_PID"
ip route add 224.0.0.0/4 dev vA
nsenter -t "$bpid" -n -- ip route add 224.0.0.0/4 dev vB
# rank 0 in host B, rank 1 in host A
printf '10.77.1.2 slots=1\n10.77.1.1 slots=1\n' > "$work/hosts"
# mpirun runs in host B (its rank 0 is local to it) and starts its daemon in host A by the agent
export TWO_HOSTS_A_PID=$$ TWO_HOSTS_A_ADDR=10.77.1.1
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 OMP_WAIT_POLICY=passive
mpi() {
  nsenter -t "$bpid" -n -u -- \
  mpirun -np 2 --map-by node --hostfile "$work/hosts" --mca plm_rsh_agent "$here/ns_agent.sh" \
    --mca btl self,tcp --mca btl_tcp_if_include 10.77.1.0/24 --mca oob_tcp_if_include 10.77.1.0/24 \
    --mca mpi_yield_when_idle 1 "$@"
}
placed="$(mpi sh -c 'echo "$OMPI_COMM_WORLD_RANK $(hostname)"' | sort | tr '\n' ' ')"
echo "ranks on: $placed"
[ "$placed" = "0 hostb 1 hosta " ] || { echo "FAIL: expected rank 0 on hostb and rank 1 on hosta, found: $placed"; exit 1; }

run="$work/two"
mkdir -p "$run"
"$bin/coordinator" "$src/scenes/footing_small.toml" --set dem.ranks=2 --print-effective > "$run/scene.toml"
url="udpm://239.255.76.67:$((20000 + RANDOM % 40000))?ttl=1&recv_buf_size=4194304"
id=$((RANDOM + 1))
mpi "$bin/dem_node" --lcm-url="$url" --run-id="$id" --run-dir="$run" > "$work/dem.out" 2>&1 &
pids+=($!)
"$bin/fdm_node" --lcm-url="$url" --run-id="$id" --run-dir="$run" > "$work/fdm.out" 2>&1 &
pids+=($!)
set +e
timeout 300 "$bin/coordinator" "$run/scene.toml" --lcm-url="$url" --run-id="$id" --run-dir="$run" > "$work/coord.out" 2>&1
code=$?
set -e
for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
pids=()
if [ "$code" -ne 0 ]; then
  tail -20 "$work/coord.out" "$work/dem.out"
  echo "FAIL: the two-host run ended with code $code"
  exit 1
fi
hello="$(grep -o "hello from dem: dem_node pid [0-9]* on [a-z]*" "$run/coordinator.log" || true)"
echo "coordinator: $hello"
case "$hello" in *" on hostb") ;; *) echo "FAIL: the coordinator did not hear the DEM from hostb"; exit 1 ;; esac
grep -q "effect_s.ranks.exchange" "$run/dem.log" || { echo "FAIL: the DEM did not step on ranks"; exit 1; }
fail=0
n=0
for f in "$work/one"/*.csv; do
  b="$(basename "$f")"
  n=$((n + 1))
  cmp -s "$f" "$run/$b" || { echo "FAIL: $b differs from the one-process run's"; fail=1; }
done
[ "$n" -ge 10 ] || { echo "FAIL: only $n CSV files in the reference"; fail=1; }
[ "$fail" -eq 0 ] && echo "two hosts: $n CSV files the same bytes as one process on one machine"
exit "$fail"

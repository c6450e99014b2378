# Sourced by tests/dist/two_hosts.sh and node_two_hosts.sh.
#
# two_hosts_check: exits 77 (skipped) with a reason where two hosts cannot be made here (not root,
# or no unshare, nsenter, ip or mpirun, or no namespaces allowed).
two_hosts_check() {
  for tool in unshare nsenter ip mpirun; do
    command -v "$tool" >/dev/null || { echo "SKIP: '$tool' is not installed"; exit 77; }
  done
  [ "$(id -u)" -eq 0 ] || { echo "SKIP: network namespaces need root"; exit 77; }
  unshare -n -u true 2>/dev/null || { echo "SKIP: cannot create network namespaces here"; exit 77; }
}

# two_hosts_make NET: in this process's
# own network and UTS namespaces (host A, named hosta, lo up), start host B (a holder process in
# new ones, named hostb, lo up) and join the two by a veth pair, NET.1 on vA in A and NET.2 on vB
# in B. Sets TWO_HOSTS_B_PID (the holder, for nsenter) and TWO_HOSTS_B_ADDR. Returns 77 when a
# veth pair cannot be made here.
two_hosts_make() {
  local net="$1"
  hostname hosta
  ip link set lo up
  unshare -n -u -- sh -c 'hostname hostb; exec sleep 3600' &
  TWO_HOSTS_B_PID=$!
  for _ in $(seq 50); do  # until the holder is in its namespace
    [ "$(readlink /proc/$TWO_HOSTS_B_PID/ns/net)" != "$(readlink /proc/self/ns/net)" ] && break
    sleep 0.1
  done
  if ! ip link add vA type veth peer name vB 2>/dev/null; then
    echo "SKIP: cannot create a veth pair here"
    return 77
  fi
  ip link set vB netns "$TWO_HOSTS_B_PID"
  ip addr add "$net.1/24" dev vA
  ip link set vA up
  nsenter -t "$TWO_HOSTS_B_PID" -n -- ip link set lo up
  nsenter -t "$TWO_HOSTS_B_PID" -n -- ip addr add "$net.2/24" dev vB
  nsenter -t "$TWO_HOSTS_B_PID" -n -- ip link set vB up
  TWO_HOSTS_B_ADDR="$net.2"
  export TWO_HOSTS_B_PID TWO_HOSTS_B_ADDR
}

#!/bin/sh
# Open MPI's remote-start agent (plm_rsh_agent) for tests/dist/two_hosts.sh and
# node_two_hosts.sh: called as "ns_agent.sh HOST COMMAND...", like ssh. Host B (and host A, when
# mpirun runs in B) is a network and UTS namespace entered with nsenter (its holder's pid in
# TWO_HOSTS_B_PID, TWO_HOSTS_A_PID); any other host is this one.
host="$1"
shift
if [ "$host" = "$TWO_HOSTS_B_ADDR" ]; then
  exec nsenter -t "$TWO_HOSTS_B_PID" -n -u -- sh -c "$*"
fi
if [ -n "${TWO_HOSTS_A_ADDR:-}" ] && [ "$host" = "$TWO_HOSTS_A_ADDR" ]; then
  exec nsenter -t "$TWO_HOSTS_A_PID" -n -u -- sh -c "$*"
fi
exec sh -c "$*"

#!/usr/bin/env bash
# Two "hosts" joined by a veth pair, made inside the private network namespace this script is
# started in (`unshare -rn two_hosts.sh ...`: the machine's own interfaces are never touched).
# Host A is this namespace (10.77.0.1), host B a namespace of its own (10.77.0.2); DDS talks
# UDP over the pair only (no shared memory, no loopback between them).
#   two_hosts.sh A_COMMAND B_COMMAND     (each one shell command; B's exit status is ours)
# Each command runs in a process group of its own, ended with everything it started.
set -euo pipefail
ip link set lo up
unshare -n sleep 3600 &
host_b=$!
host_a=""
cleanup() {
  [ -n "$host_a" ] && kill -TERM -- "-$host_a" 2>/dev/null || true
  kill "$host_b" 2>/dev/null || true
}
trap cleanup EXIT
sleep 0.3
ip link add hostA type veth peer name hostB
ip link set hostB netns "$host_b"
ip addr add 10.77.0.1/24 dev hostA
ip link set hostA up
ip route add 224.0.0.0/4 dev hostA
nsenter -t "$host_b" -n sh -c 'ip link set lo up && ip addr add 10.77.0.2/24 dev hostB &&
  ip link set hostB up && ip route add 224.0.0.0/4 dev hostB'
export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET FASTDDS_BUILTIN_TRANSPORTS=UDPv4
setsid sh -c "$1" &
host_a=$!
nsenter -t "$host_b" -n setsid sh -c "$2" &
consumer=$!
status=0
wait "$consumer" || status=$?
kill -TERM -- "-$consumer" 2>/dev/null || true
exit "$status"

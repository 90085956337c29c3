#!/usr/bin/env bash
# Several "hosts" on one switch, made inside the private network namespace this script is
# started in (`unshare -rn hosts.sh ...`: the machine's own interfaces are never touched).
# Host 1 is this namespace (10.77.0.1) and holds the switch, a bridge device; every further host
# is a network namespace of its own (10.77.0.2, .3, ...) joined to it by a veth pair. DDS talks
# UDP over the switch only (no shared memory, no loopback between hosts).
#   hosts.sh CMD_1 CMD_2 [CMD_3 ...]   (one shell command per host; the last one's exit status
#                                       is ours, the others are ended when it ends)
# Each command runs in a process group of its own, ended with everything it started.
set -euo pipefail
ip link set lo up
ip link add switch type bridge
ip addr add 10.77.0.1/24 dev switch
ip link set switch up
ip route add 224.0.0.0/4 dev switch
namespaces=()
groups=()
cleanup() {
  for group in "${groups[@]}"; do kill -TERM -- "-$group" 2>/dev/null || true; done
  for ns in "${namespaces[@]}"; do kill "$ns" 2>/dev/null || true; done
}
trap cleanup EXIT
for ((host = 2; host <= $#; host++)); do
  unshare -n sleep 3600 &
  namespaces+=("$!")
done
sleep 0.3
for ((host = 2; host <= $#; host++)); do
  ns=${namespaces[$((host - 2))]}
  ip link add "port$host" type veth peer name "eth$host"
  ip link set "port$host" master switch up
  ip link set "eth$host" netns "$ns"
  nsenter -t "$ns" -n sh -c "ip link set lo up && ip addr add 10.77.0.$host/24 dev eth$host &&
    ip link set eth$host up && ip route add 224.0.0.0/4 dev eth$host"
done
export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET FASTDDS_BUILTIN_TRANSPORTS=UDPv4
commands=("$@")
last=$(($# - 1))
for ((index = 0; index < last; index++)); do
  if ((index == 0)); then
    setsid sh -c "${commands[0]}" &
  else
    nsenter -t "${namespaces[$((index - 1))]}" -n setsid sh -c "${commands[$index]}" &
  fi
  groups+=("$!")
done
if ((last == 0)); then
  setsid sh -c "${commands[$last]}" &
else
  nsenter -t "${namespaces[$((last - 1))]}" -n setsid sh -c "${commands[$last]}" &
fi
final=$!
groups+=("$final")
status=0
wait "$final" || status=$?
exit "$status"

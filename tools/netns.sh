#!/usr/bin/env bash
# Run a command where DDS can reach nobody but this machine: in a private network namespace
# with only loopback when the kernel allows it, else with ROS 2 discovery limited to localhost.
set -u
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
if [ "${HIROS_IN_NETNS:-0}" != 1 ] && unshare -rn true 2>/dev/null; then
  export HIROS_IN_NETNS=1
  exec unshare -rn sh -c 'ip link set lo up && exec "$@"' sh "$@"
fi
exec "$@"

"""Listener side of the live play test: print every raw message of the given topics, and the
/clock values, until the expected count arrived or a deadline passed."""

from __future__ import annotations

import sys
import time

import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock


def main() -> int:
    expected = int(sys.argv[1])
    topics = sys.argv[2:]
    rclpy.init()
    node = rclpy.create_node("hiros_play_listener")
    lines: list[str] = []
    clocks: list[int] = []
    for topic in topics:
        node.create_subscription(
            SkeletonGroup,
            topic,
            lambda data, t=topic: lines.append(f"{t} {bytes(data).hex()}"),
            QoSProfile(depth=1000),
            raw=True,
        )
    node.create_subscription(
        Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec), 100
    )
    print("ready", flush=True)
    deadline = time.monotonic() + 60
    while len(lines) < expected and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    for line in lines:
        print(line)
    print(f"clock {len(clocks)} {min(clocks, default=0)} {max(clocks, default=0)}")
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Late subscriber of the play test: once ``count`` messages of a camera topic came, subscribe
to ``/hiros/calibration`` (transient-local, as a latched topic's subscriber asks) and print
what it gets, or ``calibration none`` after a deadline."""

from __future__ import annotations

import sys
import time

import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String


def main() -> int:
    count, camera_topic = int(sys.argv[1]), sys.argv[2]
    rclpy.init()
    node = rclpy.create_node("hiros_play_late_listener")
    frames: list[bytes] = []
    calibrations: list[str] = []
    node.create_subscription(SkeletonGroup, camera_topic, frames.append, 100, raw=True)
    print("ready", flush=True)
    deadline = time.monotonic() + 60
    while len(frames) < count and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(String, "/hiros/calibration", lambda m: calibrations.append(m.data),
                             latched)  # fmt: skip
    deadline = time.monotonic() + 30
    while not calibrations and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(f"frames before subscribing {len(frames)}")
    print(f"calibration {calibrations[0] if calibrations else 'none'}")
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

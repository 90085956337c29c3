"""Records raw /hiros/filter messages and their arrival times until quiet for a while."""

from __future__ import annotations

import struct
import sys
import time

import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup
from rclpy.qos import QoSProfile


def main(path: str, quiet: float, deadline: float) -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_test_recorder")
    received: list[bytes] = []
    arrivals: list[float] = []

    def keep(data: bytes) -> None:
        received.append(data)
        arrivals.append(time.time())

    node.create_subscription(SkeletonGroup, "/hiros/filter", keep, QoSProfile(depth=1000), raw=True)
    print("recorder ready", flush=True)
    end = time.monotonic() + deadline
    last = None
    while time.monotonic() < end:
        count = len(received)
        rclpy.spin_once(node, timeout_sec=0.05)
        if len(received) != count:
            if last is None:
                print("first output", flush=True)
            last = time.monotonic()
        if last is not None and time.monotonic() - last > quiet:
            break
    with open(path, "wb") as stream:
        for arrival, data in zip(arrivals, received, strict=True):
            stream.write(struct.pack("<dI", arrival, len(data)) + data)
    print(f"recorded {len(received)}", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], float(sys.argv[2]), float(sys.argv[3])))

"""Records raw /hiros/filter messages and their arrival times until quiet for a while.

  recorder.py OUT QUIET DEADLINE [NODE,NODE,...]

With node names, it first waits (within DEADLINE) until each of them is in the ROS graph with
its subscriptions made, and says "nodes ready": on a loaded machine five node processes can take
longer to start than any fixed wait.
"""

from __future__ import annotations

import struct
import sys
import time

import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup
from rclpy.qos import QoSProfile


def _wait_for_nodes(node: rclpy.node.Node, names: list[str], end: float) -> None:
    """Spin until every node in ``names`` has subscriptions, or until ``end`` (monotonic)."""
    waiting = set(names)
    while waiting and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
        present = {name for name, _ in node.get_node_names_and_namespaces()}
        waiting = {
            name
            for name in waiting
            if name not in present or not node.get_subscriber_names_and_types_by_node(name, "/")
        }
    print("nodes ready" if not waiting else f"nodes missing: {sorted(waiting)}", flush=True)


def main(path: str, quiet: float, deadline: float, nodes: str = "") -> int:
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
    if nodes:
        _wait_for_nodes(node, nodes.split(","), end)
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
    sys.exit(main(sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), *sys.argv[4:5]))

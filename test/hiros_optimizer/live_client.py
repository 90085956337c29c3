"""Client side of the live optimizer -> filter test: frames in, services called, frames out.

Publishes a rigidly moving person as track 3 on /hiros/merger, reads /hiros/filter, calls
/optimizer/change_id (3 -> 0) and /optimizer/calibrate, and prints what it saw on one line.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from hiros_skeleton_msgs.srv import Calibrate, ChangeId
from rclpy.qos import QoSProfile

from hiros_core.codec import decode_group, encode_group
from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns

RATE = 30.0


def frame(index: int, track_id: int) -> bytes:
    pose = np.random.default_rng(0).normal(scale=0.3, size=(32, 3))
    t = index / RATE
    skeleton = Skeleton.from_positions(
        pose + np.array([0.5 * t, 0.0, 0.0]), skeleton_id=track_id, src_time_ns=sec_to_ns(t)
    )
    return encode_group(SkeletonGroup(sec_to_ns(t), "world", [skeleton]))


def call(node, client, request):
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=10)
    return future.result().ok


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_body_client")
    received: list[SkeletonGroup] = []
    subscription = node.create_subscription(
        SkeletonGroupMsg,
        "/hiros/filter",
        lambda d: received.append(decode_group(d)),
        QoSProfile(depth=200),
        raw=True,
    )
    publisher = node.create_publisher(SkeletonGroupMsg, "/hiros/merger", QoSProfile(depth=200))
    calibrate = node.create_client(Calibrate, "/optimizer/calibrate")
    change_id = node.create_client(ChangeId, "/optimizer/change_id")
    deadline = time.monotonic() + 60
    while (
        publisher.get_subscription_count() == 0
        or subscription.get_publisher_count() == 0  # the filter's writer matched our reader
        or not calibrate.service_is_ready()
        or not change_id.service_is_ready()
        or node.count_subscribers("/hiros/optimizer") == 0  # the filter, between the nodes
    ):
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("nodes not discovered", file=sys.stderr)
            return 1
    settle = time.monotonic() + 2.0  # let the optimizer -> filter link match too
    while time.monotonic() < settle:
        rclpy.spin_once(node, timeout_sec=0.1)

    def publish_and_wait(index: int, patience: float = 5.0) -> None:
        """One frame, then wait for its output: a loaded machine must not lose frames."""
        expected = len(received) + 1
        publisher.publish(frame(index, 3))
        wait_until = time.monotonic() + patience
        while len(received) < expected and time.monotonic() < wait_until:
            rclpy.spin_once(node, timeout_sec=0.05)

    # The optimizer's writer may match the filter's reader after the graph says both exist
    # (a loaded machine): frames sent before that are lost between the nodes, not by them.
    # So the count starts with the first frame that comes through.
    first = 0
    while not received and first < 60:
        publish_and_wait(first, patience=1.0)
        first += 1
    first -= 1
    for index in range(first + 1, first + 90):
        publish_and_wait(index)
    steady = received[min(len(received), 90) - 1].skeletons[0]
    velocity = steady.velocities[steady.marker_present].mean(axis=0)
    moved = call(node, change_id, ChangeId.Request(from_id=3, to_id=0))
    unknown = call(node, change_id, ChangeId.Request(from_id=42, to_id=1))
    for index in range(first + 90, first + 95):
        publish_and_wait(index)
    recalibrated = call(node, calibrate, Calibrate.Request(track_ids=[0]))
    last = received[-1].skeletons[0]
    print(
        f"received {len(received)} change_id {moved} unknown {unknown} "
        f"calibrate {recalibrated} last_id {last.id} vx {velocity[0]:.3f}"
    )
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

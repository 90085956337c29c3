"""Driver side of the live bridge test: publish Azure-driver MarkerArrays (good and bad) as
raw CDR on two cameras, collect the bridge's SkeletonGroups, print them as CDR hex lines."""

from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from rclpy.qos import QoSProfile
from visualization_msgs.msg import MarkerArray

from hiros_azure_bridge import group_to_driver_markers
from hiros_core.codec import MarkerArrayData, encode_marker_array
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

CAMERAS = ("k01", "k02")
FRAMES = 12
T0 = 1_700_000_000_000_000_000


def driver_messages(camera: str) -> list[bytes]:
    """What a driver would publish, with a repeated stamp, an empty array and NaN joints."""
    rng = np.random.default_rng(len(camera) + int(camera[-1]))
    frame = f"{camera}_depth_camera_link"
    out = []
    for index in range(FRAMES):
        stamp = T0 + index * 33_333_333
        skeletons = [
            Skeleton.from_positions(
                rng.normal([0, 0, 2.5], 0.3, size=(32, 3)),
                AZURE_KINECT,
                skeleton_id=body,
                src_time_ns=stamp,
                src_frame=frame,
                confidences=rng.integers(0, 4, 32) / 3,
            )
            for body in (1, 2)
        ]
        data = group_to_driver_markers(SkeletonGroup(stamp, frame, skeletons))
        if index == 4:
            data.poses[7, 0] = np.nan  # a NaN joint: dropped, the rest kept
        out.append(encode_marker_array(data))
        if index == 6:
            out.append(out[-1])  # the same message twice: repeated stamp
        if index == 8:
            out.append(encode_marker_array(MarkerArrayData.new(0)))  # empty array
    return out


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_bridge_client")
    received: dict[str, list[bytes]] = {c: [] for c in CAMERAS}
    publishers = {}
    subscriptions = []
    for camera in CAMERAS:
        subscription = node.create_subscription(
            SkeletonGroupMsg,
            f"/{camera}/skeletons",
            lambda data, c=camera: received[c].append(bytes(data)),
            QoSProfile(depth=100),
            raw=True,
        )
        subscriptions.append(subscription)
        publishers[camera] = node.create_publisher(
            MarkerArray, f"/{camera}/body_tracking_data", QoSProfile(depth=100)
        )
    deadline = time.monotonic() + 60
    while any(p.get_subscription_count() == 0 for p in publishers.values()) or any(
        s.get_publisher_count() == 0 for s in subscriptions
    ):
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("bridge not discovered", file=sys.stderr)
            return 2
    # Both ends have matched ours; give the bridge's own writers the same moment to match our
    # readers (volatile topics deliver nothing to a reader its writer has not matched yet).
    settle = time.monotonic() + 1.0
    while time.monotonic() < settle:
        rclpy.spin_once(node, timeout_sec=0.05)
    for camera, publisher in publishers.items():
        for raw in driver_messages(camera):
            publisher.publish(raw)
            rclpy.spin_once(node, timeout_sec=0.02)
    deadline = time.monotonic() + 20
    while any(len(v) < FRAMES for v in received.values()) and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    for _ in range(10):  # anything extra would arrive now
        rclpy.spin_once(node, timeout_sec=0.05)
    for camera, messages in received.items():
        for raw in messages:
            print(f"{camera} {raw.hex()}")
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Camera side of the tracker/merger node test: two cameras publish two standing people.

Publishes raw SkeletonGroup bytes on /k01/skeletons and /k02/skeletons (identity extrinsics,
no clock offsets, so camera frame = world frame) and listens to /hiros/tracker and
/hiros/merger; prints one summary line the test reads.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from rclpy.qos import QoSProfile

from hiros_core.codec import decode_group, encode_group
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

FRAMES = 60
PEOPLE = {0: np.array([0.0, 0.0, 3.0]), 1: np.array([1.0, 0.0, 3.0])}


def pose(centre: np.ndarray) -> np.ndarray:
    offsets = np.zeros((AZURE_KINECT.n_joints, 3))
    for joint, parent in enumerate(AZURE_KINECT.parents):
        if parent >= 0:
            name = AZURE_KINECT.joint_names[joint]
            side = 0.1 if "Left" in name else -0.1 if "Right" in name else 0.0
            offsets[joint] = offsets[parent] + [side, -0.12, 0.0]
    return centre + offsets


def frame(camera: str, index: int) -> SkeletonGroup:
    stamp = 1_700_000_000_000_000_000 + index * 33_333_333
    skeletons = [
        Skeleton.from_positions(
            pose(centre),
            skeleton_id=body + 1,
            src_time_ns=stamp,
            src_frame=f"{camera}_depth_camera_link",
            confidences=np.full(AZURE_KINECT.n_joints, 2 / 3),
        )
        for body, centre in PEOPLE.items()
    ]
    return SkeletonGroup(stamp, f"{camera}_depth_camera_link", skeletons)


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_test_cameras")
    tracked: list[bytes] = []
    merged: list[bytes] = []
    qos = QoSProfile(depth=100)
    node.create_subscription(SkeletonGroupMsg, "/hiros/tracker", tracked.append, qos, raw=True)
    node.create_subscription(SkeletonGroupMsg, "/hiros/merger", merged.append, qos, raw=True)
    publishers = {
        cam: node.create_publisher(SkeletonGroupMsg, f"/{cam}/skeletons", qos)
        for cam in ("k01", "k02")
    }
    deadline = time.monotonic() + 60
    while (
        any(p.get_subscription_count() == 0 for p in publishers.values())
        or node.count_publishers("/hiros/merger") == 0
        or node.count_subscribers("/hiros/tracker") == 0
    ):
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("nodes not discovered", file=sys.stderr)
            return 2
    time.sleep(1.0)  # let the matched QoS settle before the first frame
    first = 0
    if "--calib" in sys.argv:
        # No calibration file: the first frames find no calibration; then a node named
        # "calib" publishes one as its parameters, which the tracker follows.
        first = 10
        for index in range(first):
            for camera, publisher in publishers.items():
                publisher.publish(encode_group(frame(camera, index)))
            rclpy.spin_once(node, timeout_sec=0.01)
        calib = rclpy.create_node("calib")
        for camera in publishers:
            calib.declare_parameter(f"cameras.{camera}.frame_id", f"{camera}_depth_camera_link")
            calib.declare_parameter(f"cameras.{camera}.time_offset", 0.0)
            calib.declare_parameter(f"cameras.{camera}.translation", [0.0, 0.0, 0.0])
            calib.declare_parameter(f"cameras.{camera}.rotation", [0.0, 0.0, 0.0, 1.0])
        end = time.monotonic() + 2
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            rclpy.spin_once(calib, timeout_sec=0.05)
    for index in range(first, FRAMES):
        for camera, publisher in publishers.items():
            publisher.publish(encode_group(frame(camera, index)))
        rclpy.spin_once(node, timeout_sec=0.01)
    end = time.monotonic() + 10
    while time.monotonic() < end and len(merged) < FRAMES:
        rclpy.spin_once(node, timeout_sec=0.1)
    tracked_ids = sorted({s.id for data in tracked for s in decode_group(data).skeletons})
    groups = [decode_group(data) for data in merged]
    merged_ids = sorted({s.id for g in groups for s in g.skeletons})
    error = max(
        (
            float(np.abs(s.positions[0] - PEOPLE[0 if s.positions[0, 0] < 0.5 else 1]).max())
            for g in groups
            for s in g.skeletons
        ),
        default=float("nan"),
    )
    frames = {g.frame_id for g in groups}
    print(
        f"tracked {len(tracked)} ids {tracked_ids} merged {len(groups)} ids {merged_ids} "
        f"frames {sorted(frames)} error {error:.6f}"
    )
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

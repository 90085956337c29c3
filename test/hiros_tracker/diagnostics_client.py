"""Client side of the live accounting test: good and bad frames in, /diagnostics read back.

Publishes on /k01/skeletons (reliable, so that every frame arrives): good frames of two
standing people, one with NaN detections, a repeat, one too late, undecodable bytes and one
of a camera without calibration; then waits for a /diagnostics status of the tracker that
has received them all and prints its counters as one JSON line the test reads.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from rclpy.qos import QoSProfile

from hiros_core.codec import encode_group
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

GOOD = 40


def frame(index: int, camera: str = "k01") -> SkeletonGroup:
    """Two people standing still, seen by ``camera`` at 30 Hz."""
    stamp = 1_700_000_000_000_000_000 + index * 33_333_333
    rest = np.tile([0.0, 0.0, 3.0], (AZURE_KINECT.n_joints, 1))
    rest[:, 1] -= np.linspace(0.0, 1.6, AZURE_KINECT.n_joints)
    skeletons = [
        Skeleton.from_positions(
            rest + np.array([x, 0.0, 0.0]),
            skeleton_id=body,
            src_time_ns=stamp,
            src_frame=f"{camera}_depth_camera_link",
        )
        for body, x in ((1, 0.0), (2, 1.0))
    ]
    return SkeletonGroup(stamp, f"{camera}_depth_camera_link", skeletons)


def stream() -> list[bytes]:
    """The frames to send, good and bad, in order."""
    nan = frame(GOOD // 2)
    for skeleton in nan.skeletons:
        skeleton.positions[:] = np.nan
    late = frame(0)
    late.stamp_ns += 1  # no repeat of frame 0, but older than what was processed
    bad = [encode_group(nan), encode_group(frame(5)), encode_group(late), b"\x00\x01\x00\x00bad"]
    bad.append(encode_group(frame(GOOD // 2 + 1, camera="k09")))
    good = [encode_group(frame(i)) for i in range(GOOD) if i != GOOD // 2]
    return good[: GOOD // 2] + bad + good[GOOD // 2 :]


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_test_diagnostics")
    statuses: list[dict[str, str]] = []

    def on_diagnostics(array: DiagnosticArray) -> None:
        for status in array.status:
            if status.name == "/tracker":
                values = {kv.key: kv.value for kv in status.values}
                statuses.append({"level": ord(status.level), **values})
                statuses[-1]["message"] = status.message

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    publisher = node.create_publisher(SkeletonGroupMsg, "/k01/skeletons", QoSProfile(depth=100))
    deadline = time.monotonic() + 60
    while publisher.get_subscription_count() == 0 or not statuses:
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("tracker not discovered", file=sys.stderr)
            return 2
    time.sleep(0.5)
    sent = stream()
    for data in sent:
        publisher.publish(data)
        rclpy.spin_once(node, timeout_sec=0.005)
    deadline = time.monotonic() + 20
    while not statuses or int(statuses[-1].get("received", 0)) < len(sent):
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print(f"not all received: {statuses[-1:]}", file=sys.stderr)
            return 3
    print("sent", len(sent), "diagnostics", json.dumps(statuses[-1]))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

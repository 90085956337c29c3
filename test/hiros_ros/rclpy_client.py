"""Plain rclpy side of the two-process test: message objects out, message objects back."""

from __future__ import annotations

import sys
import time

import rclpy
from hiros_skeleton_msgs.msg import Link, Marker, Skeleton, SkeletonGroup
from rclpy.qos import QoSProfile

COUNT = 20


def make_group(index: int) -> SkeletonGroup:
    group = SkeletonGroup()
    group.header.frame_id = f"k0{index % 3 + 1}_depth_camera_link"
    group.header.stamp.sec, group.header.stamp.nanosec = 1_700_000_000 + index, 123_456_789
    for person in range(index % 4 + 1):
        skeleton = Skeleton(id=person * 7, src_frame=group.header.frame_id, max_markers=32)
        skeleton.max_links, skeleton.confidence = 32, 0.25 * person
        skeleton.src_time.sec, skeleton.src_time.nanosec = 1_699_999_999, 999_999_999
        for joint in range(0, 32, 1 + person):
            marker = Marker(id=joint, confidence=0.5)
            marker.name = ("Pelvis", "SpineNaval", "SpineChest")[joint] if joint < 3 else "Neck"
            marker.center.pose.position.x = joint + index / 10
            marker.center.pose.orientation.w = 1.0
            skeleton.markers.append(marker)
            break  # one named marker keeps names consistent with the Azure layout
        link = Link(id=1, name="Pelvis-SpineNaval", parent_marker=0, child_marker=1, confidence=1.0)
        link.center.velocity.linear.z = -float(index)
        skeleton.links.append(link)
        group.skeletons.append(skeleton)
    return group


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_rclpy_client")
    received: list[SkeletonGroup] = []
    node.create_subscription(
        SkeletonGroup, "/hiros_test/out", received.append, QoSProfile(depth=50)
    )
    publisher = node.create_publisher(SkeletonGroup, "/hiros_test/in", QoSProfile(depth=50))
    deadline = time.monotonic() + 30
    while publisher.get_subscription_count() == 0 or node.count_publishers("/hiros_test/out") == 0:
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("no echo node discovered", file=sys.stderr)
            return 2
    settle = time.monotonic() + 1.0  # let the echo node's writer match our reader too
    while time.monotonic() < settle:
        rclpy.spin_once(node, timeout_sec=0.05)
    sent = [make_group(i) for i in range(COUNT)]
    for group in sent:
        publisher.publish(group)
        rclpy.spin_once(node, timeout_sec=0.02)
    while len(received) < COUNT and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    exact = 0
    for original, echoed in zip(sent, received, strict=False):
        expected = f"echo:{original.header.frame_id}"
        if echoed.header.frame_id == expected:
            echoed.header.frame_id = original.header.frame_id
            exact += echoed == original
    print(f"sent {COUNT} received {len(received)} exact {exact}")
    node.destroy_node()
    rclpy.shutdown()
    return 0 if exact == COUNT else 1


if __name__ == "__main__":
    sys.exit(main())

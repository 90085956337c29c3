"""Codec speed: our CDR codec against rclpy message objects, on the same data in one run.

Two operations per message type, each as the pipeline needs them:
* construct + serialise: numpy model -> bytes (ours) vs filling rclpy message objects from the
  same arrays and ``rclpy.serialization.serialize_message``;
* deserialise + convert: bytes -> numpy model (ours) vs ``deserialize_message`` and reading the
  fields back into numpy arrays.
Data: 4 people x 32 joints (a SkeletonGroup; and the Azure driver's MarkerArray of 128 markers).
"""

from __future__ import annotations

import numpy as np

from hiros_bench.timing import per_call_seconds
from hiros_core.codec import (
    MarkerArrayData,
    decode_group,
    decode_marker_array,
    encode_group,
    encode_marker_array,
)
from hiros_core.model import Skeleton, SkeletonGroup


def sample_group(people: int = 4, seed: int = 0) -> SkeletonGroup:
    """A realistic camera frame: ``people`` Azure Kinect skeletons with every field filled."""
    rng = np.random.default_rng(seed)
    skeletons = []
    for person in range(people):
        quaternions = rng.normal(size=(32, 4))
        skeleton = Skeleton.from_positions(
            rng.normal(size=(32, 3)) + np.array([0.0, 0.0, 3.0]),
            skeleton_id=person,
            src_time_ns=1_700_000_000_123_456_789,
            src_frame="k01_depth_camera_link",
            confidences=rng.integers(0, 3, 32) / 2,
            orientations=quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True),
        )
        skeleton.velocities[:] = rng.normal(size=(32, 3))
        skeleton.accelerations[:] = rng.normal(size=(32, 3))
        skeletons.append(skeleton)
    return SkeletonGroup(1_700_000_000_123_456_789, "k01_depth_camera_link", skeletons)


def sample_markers(group: SkeletonGroup) -> MarkerArrayData:
    """The group as the Azure Kinect driver publishes it (id = body * 100 + joint)."""
    rows = [
        (s.id, j, s.positions[j], s.orientations[j]) for s in group.skeletons for j in range(32)
    ]
    data = MarkerArrayData.new(len(rows), frame_id=group.frame_id, stamp_ns=group.stamp_ns)
    data.ids[:] = [body * 100 + joint for body, joint, _, _ in rows]
    data.poses[:, :3] = [p for _, _, p, _ in rows]
    data.poses[:, 3:] = [q for _, _, _, q in rows]
    data.lifetimes_ns[:] = 250_000_000
    return data


def _rclpy_group(group: SkeletonGroup):  # noqa: ANN202 - rclpy message type
    from hiros_skeleton_msgs.msg import Link, Marker
    from hiros_skeleton_msgs.msg import Skeleton as SkeletonMsg
    from hiros_skeleton_msgs.msg import SkeletonGroup as Msg

    def state(msg, row: np.ndarray) -> None:  # noqa: ANN001
        pose, twist, accel = msg.pose, msg.velocity, msg.acceleration
        pose.position.x, pose.position.y, pose.position.z = row[1:4].tolist()
        o = pose.orientation
        o.x, o.y, o.z, o.w = row[4:8].tolist()
        twist.linear.x, twist.linear.y, twist.linear.z = row[8:11].tolist()
        twist.angular.x, twist.angular.y, twist.angular.z = row[11:14].tolist()
        accel.linear.x, accel.linear.y, accel.linear.z = row[14:17].tolist()
        accel.angular.x, accel.angular.y, accel.angular.z = row[17:20].tolist()

    out = Msg()
    out.header.stamp.sec, out.header.stamp.nanosec = divmod(group.stamp_ns, 1_000_000_000)
    out.header.frame_id = group.frame_id
    for skeleton in group.skeletons:
        msg = SkeletonMsg(id=skeleton.id, src_frame=skeleton.src_frame)
        msg.src_time.sec, msg.src_time.nanosec = divmod(skeleton.src_time_ns, 1_000_000_000)
        msg.max_markers, msg.max_links = skeleton.max_markers, skeleton.max_links
        msg.confidence = skeleton.confidence
        for j in np.flatnonzero(skeleton.marker_present):
            marker = Marker(id=int(j), name=skeleton.layout.joint_names[j])
            marker.confidence = float(skeleton.markers[j, 0])
            state(marker.center, skeleton.markers[j])
            msg.markers.append(marker)
        for link_id in np.flatnonzero(skeleton.link_present):
            link = Link(id=int(link_id), name=skeleton.layout.link_names[link_id])
            link.parent_marker, link.child_marker = skeleton.layout.parents[link_id], int(link_id)
            link.confidence = float(skeleton.links[link_id, 0])
            state(link.center, skeleton.links[link_id])
            msg.links.append(link)
        out.skeletons.append(msg)
    return out


def _rclpy_group_to_numpy(msg) -> list[np.ndarray]:  # noqa: ANN001
    result = []
    for skeleton in msg.skeletons:
        rows = np.full((skeleton.max_markers, 20), np.nan)
        for marker in skeleton.markers:
            p, o = marker.center.pose.position, marker.center.pose.orientation
            v, a = marker.center.velocity, marker.center.acceleration
            rows[marker.id] = [
                marker.confidence, p.x, p.y, p.z, o.x, o.y, o.z, o.w,
                v.linear.x, v.linear.y, v.linear.z, v.angular.x, v.angular.y, v.angular.z,
                a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y, a.angular.z,
            ]  # fmt: skip
        result.append(rows)
    return result


def _rclpy_markers(data: MarkerArrayData):  # noqa: ANN202
    from visualization_msgs.msg import Marker, MarkerArray

    out = MarkerArray()
    for i in range(len(data)):
        marker = Marker(id=int(data.ids[i]), type=int(data.types[i]), action=int(data.actions[i]))
        marker.header.frame_id = data.frame_ids[i]
        marker.header.stamp.sec, marker.header.stamp.nanosec = divmod(int(data.stamps_ns[i]), 10**9)
        p, o = marker.pose.position, marker.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = data.poses[i].tolist()
        marker.scale.x, marker.scale.y, marker.scale.z = data.scales[i].tolist()
        c = marker.color
        c.r, c.g, c.b, c.a = data.colors[i].tolist()
        marker.lifetime.sec, marker.lifetime.nanosec = divmod(int(data.lifetimes_ns[i]), 10**9)
        out.markers.append(marker)
    return out


def _rclpy_markers_to_numpy(msg) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    ids = np.array([m.id for m in msg.markers], dtype=np.int32)
    poses = np.array(
        [
            [m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.x,
             m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w]
            for m in msg.markers
        ]
    )  # fmt: skip
    return ids, poses


def measure() -> list[tuple[str, float, float]]:
    """(operation, rclpy seconds, hiros seconds) for the four codec operations."""
    from hiros_skeleton_msgs.msg import SkeletonGroup as GroupMsg
    from rclpy.serialization import deserialize_message, serialize_message
    from visualization_msgs.msg import MarkerArray

    group = sample_group()
    markers = sample_markers(group)
    group_bytes, marker_bytes = encode_group(group), encode_marker_array(markers)
    return [
        (
            "SkeletonGroup 4x32 construct+serialise",
            per_call_seconds(lambda: serialize_message(_rclpy_group(group))),
            per_call_seconds(lambda: encode_group(group)),
        ),
        (
            "SkeletonGroup 4x32 deserialise+numpy",
            per_call_seconds(
                lambda: _rclpy_group_to_numpy(deserialize_message(group_bytes, GroupMsg))
            ),
            per_call_seconds(lambda: decode_group(group_bytes)),
        ),
        (
            "MarkerArray 128 construct+serialise",
            per_call_seconds(lambda: serialize_message(_rclpy_markers(markers))),
            per_call_seconds(lambda: encode_marker_array(markers)),
        ),
        (
            "MarkerArray 128 deserialise+numpy",
            per_call_seconds(
                lambda: _rclpy_markers_to_numpy(deserialize_message(marker_bytes, MarkerArray))
            ),
            per_call_seconds(lambda: decode_marker_array(marker_bytes)),
        ),
    ]


def run(console, quick: bool = False) -> list[str]:  # noqa: ANN001 - rich Console
    """Print the table and return its lines; the last line gives the smallest ratio."""
    rows = measure()
    lines = [f"{'operation':42s} {'rclpy ms':>10s} {'hiros ms':>10s} {'ratio':>7s}"]
    for name, baseline, ours in rows:
        lines.append(
            f"{name:42s} {baseline * 1e3:10.3f} {ours * 1e3:10.3f} {baseline / ours:6.1f}x"
        )
    ratios = [baseline / ours for _, baseline, ours in rows]
    group_ratio, marker_ratio = min(ratios[:2]), min(ratios[2:])
    lines.append(
        f"codec speed-up vs rclpy: SkeletonGroup {group_ratio:.1f}x, "
        f"MarkerArray {marker_ratio:.1f}x "
        f"(min {min(ratios):.1f}x)"
    )
    for line in lines:
        console.print(line, highlight=False)
    return lines

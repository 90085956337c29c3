"""Data in and out: bridge and recording throughput in messages per second.

Each figure stands beside a baseline doing the same job with rclpy message objects or
``rosbags``, measured in the same run:

* bridge: one Azure-driver MarkerArray (2 people × 32 joints) in CDR -> SkeletonGroup CDR,
  as the official driver publishes it (empty ``text``) and as forks do (confidence level in
  ``text``, different in every frame). hiros: ``DriverBridge.update_bytes`` (what the bridge
  node runs: the columns it needs decoded, then converted) + ``encode_group``. Baseline: what
  a plain rclpy node does: ``deserialize_message``, a loop over the markers filling
  hiros_skeleton_msgs objects (positions and confidences only, no links),
  ``serialize_message``.
* write: a SkeletonGroup -> driver MarkerArray -> MCAP. hiros: ``group_to_driver_markers`` +
  ``encode_marker_array`` + ``RecordingWriter``. Baseline: rclpy Marker objects +
  ``serialize_message`` + the same writer.
* read: an MCAP of (official) driver MarkerArrays -> per-camera groups. hiros:
  ``iter_groups``. Baseline: ``rosbags`` AnyReader deserialising each message into objects
  (no conversion to groups).
* convert: ``hiros convert`` of the UNIPD-BPE take (or a synthetic CSV), end to end, alone.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hiros_bench.timing import per_call_seconds
from hiros_core.codec import encode_group, encode_marker_array
from hiros_core.driver import DriverBridge, group_to_driver_markers
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import MARKER_ARRAY, RecordingWriter, iter_groups

__all__ = ["measure", "run"]

_T0 = 1_700_000_000_000_000_000
_UNIPD = Path(__file__).resolve().parents[2] / "shared" / "data" / "unipd_bpe_sample"


def _frames(count: int, people: int = 2) -> list[SkeletonGroup]:
    """``count`` camera frames of ``people`` random-walking Azure Kinect skeletons."""
    rng = np.random.default_rng(0)
    base = rng.normal([0.0, 0.0, 2.5], 0.3, size=(people, AZURE_KINECT.n_joints, 3))
    frames = []
    for index in range(count):
        stamp = _T0 + index * 33_333_333
        base += rng.normal(0.0, 0.005, base.shape)
        frames.append(
            SkeletonGroup(
                stamp,
                "k01_depth_camera_link",
                [
                    Skeleton.from_positions(
                        base[p],
                        skeleton_id=p + 1,
                        src_time_ns=stamp,
                        src_frame="k01_depth_camera_link",
                        confidences=rng.integers(0, 4, AZURE_KINECT.n_joints) / 3,
                    )
                    for p in range(people)
                ],
            )
        )
    return frames


def _rclpy_bridge(raw: bytes) -> bytes:
    """The baseline bridge: rclpy objects in, rclpy objects out."""
    from hiros_skeleton_msgs.msg import Marker, Skeleton, SkeletonGroup
    from rclpy.serialization import deserialize_message, serialize_message
    from visualization_msgs.msg import MarkerArray

    markers = deserialize_message(raw, MarkerArray).markers
    out = SkeletonGroup()
    out.header = markers[0].header
    bodies: dict[int, Any] = {}
    for driver_marker in markers:
        body, joint = divmod(driver_marker.id, 100)
        skeleton = bodies.get(body)
        if skeleton is None:
            skeleton = Skeleton(id=body, src_frame=driver_marker.header.frame_id)
            skeleton.src_time, skeleton.max_markers, skeleton.max_links = (
                driver_marker.header.stamp, 32, 32,
            )  # fmt: skip
            bodies[body] = skeleton
            out.skeletons.append(skeleton)
        text = driver_marker.text
        marker = Marker(id=joint, confidence=int(text) / 3 if text else math.nan)
        marker.center.pose = driver_marker.pose
        skeleton.markers.append(marker)
    return serialize_message(out)


def _rclpy_markers(group: SkeletonGroup) -> bytes:
    """The baseline writer's message: rclpy Marker objects, serialised."""
    from rclpy.serialization import serialize_message
    from visualization_msgs.msg import Marker, MarkerArray

    out = MarkerArray()
    sec, nanosec = divmod(group.stamp_ns, 1_000_000_000)
    for skeleton in group.skeletons:
        for joint in np.flatnonzero(skeleton.marker_present):
            marker = Marker(id=int(skeleton.id * 100 + joint), type=Marker.SPHERE)
            marker.header.frame_id = group.frame_id
            marker.header.stamp.sec, marker.header.stamp.nanosec = sec, nanosec
            position, orientation = marker.pose.position, marker.pose.orientation
            position.x, position.y, position.z = skeleton.positions[joint].tolist()
            orientation.w = 1.0
            marker.scale.x = marker.scale.y = marker.scale.z = 0.05
            marker.color.a = 1.0
            marker.lifetime.nanosec = 250_000_000
            marker.text = str(round(skeleton.confidences[joint] * 3))
            out.markers.append(marker)
    return serialize_message(out)


def _per_message(function: Any, count: int) -> float:
    """Seconds per message of a function that handles ``count`` messages per call."""
    return per_call_seconds(function, repeats=3, budget=0.6) / count


def _write(path: Path, frames: list[SkeletonGroup], *, baseline: bool, texts: bool = True) -> None:
    with RecordingWriter(path) as writer:
        for group in frames:
            if baseline:
                raw = _rclpy_markers(group)
            else:
                markers = group_to_driver_markers(group)
                if not texts:
                    markers.texts = [""] * len(markers)
                raw = encode_marker_array(markers)
            writer.write("/k01/body_tracking_data", MARKER_ARRAY, raw, group.stamp_ns)


def _read_rosbags(path: Path) -> int:
    from rosbags.highlevel import AnyReader

    count = 0
    with AnyReader([path]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            count += 1
    return count


def _convert_rate(folder: Path) -> tuple[str, float]:
    """Messages per second of ``convert`` on the UNIPD take (or a generic CSV stand-in)."""
    from hiros_convert import convert

    source = _UNIPD / "sbj01_bend1KinectPos.csv"
    name = "UNIPD-BPE CSV (355 frames)"
    if not source.is_file():
        source, name = folder / "generic.csv", "generic CSV (300 frames)"
        rows = ["camera,stamp_ns,body_id,joint,x,y,z"]
        rows += [f"k01,{i * 33_333_333},1,{j},0.1,0.2,2.0" for i in range(300) for j in range(32)]
        source.write_text("\n".join(rows) + "\n")
    runs = []
    for attempt in range(3):
        start = time.perf_counter()
        counts = convert(source, folder / f"convert_{attempt}.mcap")
        runs.append((time.perf_counter() - start) / sum(counts.values()))
    return name, min(runs)


def measure(quick: bool = False) -> list[tuple[str, float, float]]:
    """(job, baseline s/message, hiros s/message) rows, plus the convert figure (no baseline)."""
    frames = _frames(40 if quick else 100)
    rows = []
    for label, with_text in (("official driver", False), ("confidence in text", True)):
        raw = []
        for group in frames:
            markers = group_to_driver_markers(group)
            if not with_text:
                markers.texts = [""] * len(markers)
            raw.append(encode_marker_array(markers))

        def ours_bridge(raw: list[bytes] = raw) -> None:
            bridge = DriverBridge()
            for data in raw:
                encode_group(bridge.update_bytes(data))

        def baseline_bridge(raw: list[bytes] = raw) -> None:
            for data in raw:
                _rclpy_bridge(data)

        rows.append(
            (
                f"bridge 2x32 -> SkeletonGroup, {label}",
                _per_message(baseline_bridge, len(raw)),
                _per_message(ours_bridge, len(raw)),
            )
        )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        counter = iter(range(10**6))

        def write(baseline: bool) -> None:
            _write(folder / f"w{next(counter)}.mcap", frames, baseline=baseline)

        rows.append(
            (
                "write group -> driver MarkerArray -> MCAP",
                _per_message(lambda: write(True), len(frames)),
                _per_message(lambda: write(False), len(frames)),
            )
        )
        recording = folder / "read.mcap"
        _write(recording, frames, baseline=False, texts=False)
        rows.append(
            (
                "read MCAP driver topic -> groups, official driver",
                _per_message(lambda: _read_rosbags(recording), len(frames)),
                _per_message(lambda: sum(1 for _ in iter_groups(recording)), len(frames)),
            )
        )
        name, seconds = _convert_rate(folder)
        rows.append((f"convert {name} end to end", math.nan, seconds))
    return rows


def run(console: Any, quick: bool = False) -> list[str]:
    """Print the table and return its lines (messages per second; ratio = hiros / baseline)."""
    rows = measure(quick)
    lines = [f"{'job':48s} {'baseline msg/s':>14s} {'hiros msg/s':>12s} {'ratio':>7s}"]
    for name, baseline, ours in rows:
        if math.isnan(baseline):
            lines.append(f"{name:48s} {'-':>14s} {1 / ours:12.0f} {'-':>7s}")
        else:
            lines.append(
                f"{name:48s} {1 / baseline:14.0f} {1 / ours:12.0f} {baseline / ours:6.1f}x"
            )
    for line in lines:
        console.print(line, highlight=False)
    return lines

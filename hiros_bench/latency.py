"""Latency probe (run by ``hiros bench pipeline`` inside a loopback-only network namespace).

Starts the pipeline (composed ``pipeline`` node, or ``tracker``, ``merger``, ``optimizer`` and
``filter`` as four processes), publishes three cameras x 30 Hz x 4 people of SkeletonGroups
stamped with the current time on ``/<cam>/skeletons``, and measures, for every group received
on ``/hiros/filter``, receive time minus its header stamp (the camera stamp it came from).
The tracker's out-of-order window adds its length to the latency by design; the probe reports
the pipeline with ``tracker.max_delay`` set to 0 (the low-latency setting) and says so.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hiros_core.calibration import Calibration, CameraCalibration, save_calibration
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

CAMERAS = ("k01", "k02", "k03")
RATE = 30.0
PEOPLE = 4


def _executable(name: str) -> str:
    return str(Path(sys.prefix) / "bin" / name)


def _start_pipeline(mode: str, calibration: Path) -> list[subprocess.Popen]:
    cameras = "[" + ", ".join(CAMERAS) + "]"
    common = ["--ros-args", "--log-level", "warn"]
    if mode == "composed":
        commands = [
            [_executable("pipeline"), *common, "-p", "input:=skeletons",
             "-p", f"cameras:={cameras}", "-p", f"calibration_file:={calibration}",
             "-p", "tracker.max_delay:=0.0"],
        ]  # fmt: skip
    else:
        commands = [
            [_executable("tracker"), *common, "-p", f"cameras:={cameras}",
             "-p", f"calibration_file:={calibration}", "-p", "max_delay:=0.0"],
            [_executable("merger"), *common],
            [_executable("optimizer"), *common],
            [_executable("filter"), *common],
        ]  # fmt: skip
    return [subprocess.Popen(command, stdout=subprocess.DEVNULL) for command in commands]


def _walking_people(t: float) -> np.ndarray:
    """(P, 32, 3) skeletons two metres apart, swaying, in the camera frame (z forward)."""
    rng = np.random.default_rng(0)
    body = rng.normal(scale=0.25, size=(32, 3)) * [1.0, 2.5, 0.4]
    offsets = np.array([[x, 0.0, 3.0] for x in np.linspace(-2.0, 2.0, PEOPLE)])
    sway = np.array([0.3 * np.sin(0.8 * t), 0.0, 0.2 * np.cos(0.5 * t)])
    return body[None] + offsets[:, None] + sway


def _camera_group(camera: str, stamp_ns: int) -> SkeletonGroup:
    frame = f"{camera}_depth_camera_link"
    skeletons = [
        Skeleton.from_positions(
            person, AZURE_KINECT, skeleton_id=i, src_time_ns=stamp_ns, src_frame=frame,
            confidences=np.full(32, 2 / 3),
        )
        for i, person in enumerate(_walking_people(stamp_ns * 1e-9))
    ]  # fmt: skip
    return SkeletonGroup(stamp_ns, frame, skeletons)


class _Probe:
    """The rclpy side: camera publishers, the /hiros/filter subscriber, the latencies."""

    def __init__(self) -> None:
        import rclpy
        from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
        from rclpy.qos import QoSProfile, qos_profile_sensor_data

        from hiros_ros import make_executor

        rclpy.init()
        self.rclpy = rclpy
        self.node = rclpy.create_node("hiros_latency_probe")
        self.executor = make_executor()  # the nodes' own executor, for the same wake-up cost
        self.executor.add_node(self.node)
        self.latencies: list[float] = []
        self.node.create_subscription(
            SkeletonGroupMsg, "/hiros/filter", self.on_output, QoSProfile(depth=100), raw=True
        )
        self.publishers = {
            camera: self.node.create_publisher(
                SkeletonGroupMsg, f"/{camera}/skeletons", qos_profile_sensor_data
            )
            for camera in CAMERAS
        }

    def on_output(self, data: bytes) -> None:
        from hiros_core.codec import decode_group

        received = time.time_ns()
        self.latencies.append((received - decode_group(data).stamp_ns) * 1e-6)

    def discovered(self) -> bool:
        wired = all(p.get_subscription_count() > 0 for p in self.publishers.values())
        return wired and self.node.count_publishers("/hiros/filter") > 0

    def spin_until(self, deadline: float) -> None:
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=max(0.0, deadline - time.monotonic()))

    def stream(self, seconds: float, warmup: float = 2.0) -> None:
        from hiros_core.codec import encode_group

        period = 1.0 / (RATE * len(CAMERAS))
        start = time.monotonic()
        frame = 0
        while time.monotonic() - start < seconds + warmup:
            camera = CAMERAS[frame % len(CAMERAS)]
            group = _camera_group(camera, time.time_ns())
            # Stamped when sent, as a camera driver does: building the people is the probe's
            # work, not the pipeline's latency.
            group.stamp_ns = time.time_ns()
            for skeleton in group.skeletons:
                skeleton.src_time_ns = group.stamp_ns
            self.publishers[camera].publish(encode_group(group))
            if time.monotonic() - start < warmup:
                self.latencies.clear()
            frame += 1
            self.spin_until(start + frame * period)
        self.spin_until(time.monotonic() + 0.5)

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.shutdown()


def probe(mode: str, seconds: float) -> int:
    """Run the probe; prints ``latency <mode>: p50 ... p95 ...``."""
    folder = Path(tempfile.mkdtemp())
    cameras = {c: CameraCalibration(f"{c}_depth_camera_link") for c in CAMERAS}
    save_calibration(Calibration("k01", cameras=cameras), folder / "calib.yaml")
    processes = _start_pipeline(mode, folder / "calib.yaml")
    probe = _Probe()
    try:
        deadline = time.monotonic() + 60
        while not probe.discovered():
            probe.spin_until(time.monotonic() + 0.1)
            if time.monotonic() > deadline:
                print("pipeline not discovered", file=sys.stderr)
                return 2
        probe.stream(seconds)
    finally:
        probe.close()
        for process in processes:
            process.terminate()
        for process in processes:
            process.wait(timeout=20)
    if not probe.latencies:
        print("no output received from /hiros/filter", file=sys.stderr)
        return 1
    values = np.array(probe.latencies)
    label = "composed (one process)" if mode == "composed" else "separate nodes (4 processes)"
    print(
        f"latency {label}, tracker.max_delay=0: p50 {np.percentile(values, 50):.2f} ms, "
        f"p95 {np.percentile(values, 95):.2f} ms over {values.size} outputs "
        f"(target p95 <= {5 if mode == 'composed' else 15} ms)"
    )
    return 0


def main() -> int:
    """``python -m hiros_bench.latency --mode composed|nodes --seconds S``."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mode", choices=["composed", "nodes"], default="composed")
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return probe(args.mode, args.seconds)


if __name__ == "__main__":
    sys.exit(main())

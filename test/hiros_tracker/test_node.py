"""The tracker and merger nodes on live topics: two cameras, two people, calibration file."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hiros_core.calibration import Calibration, CameraCalibration, save_calibration

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def _params(*params: str) -> list[str]:
    return [arg for p in params for arg in ("-p", p)]


def test_tracker_and_merger_nodes_on_live_topics(ros_processes, tmp_path: Path) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    calibration = Calibration(
        "k01",
        "world",
        {
            cam: CameraCalibration(frame_id=f"{cam}_depth_camera_link", translation=np.zeros(3))
            for cam in ("k01", "k02")
        },
    )
    path = tmp_path / "calibration.yaml"
    save_calibration(calibration, path)
    tracker = _params("cameras:=[k01, k02]", f"calibration_file:={path}", "min_hits:=3")
    ros_processes.node("hiros_tracker.node", *tracker)
    ros_processes.node("hiros_merger.node", *_params(f"calibration_file:={path}"))
    client = ros_processes.client(HERE / "ros_cameras.py")
    logs = [ros_processes.stop()]
    log = client.stdout + client.stderr + "".join(logs)
    assert client.returncode == 0, log
    summary = re.search(r"ids \[(.*)\] merged (\d+) ids \[(.*)\] frames (.*) error (\S+)", log)
    assert summary, log
    assert summary.group(1) == "0, 1", log
    assert int(summary.group(2)) > 20, log
    assert summary.group(3) == "0, 1", log
    assert summary.group(4) == "['world']", log
    assert float(summary.group(5)) < 1e-6, log
    assert "Traceback" not in log, log


def test_tracker_node_follows_the_calib_node_parameters(ros_processes) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    ros_processes.node("hiros_tracker.node", *_params("cameras:=[k01, k02]", "min_hits:=3"))
    ros_processes.node("hiros_merger.node")
    client = ros_processes.client(HERE / "ros_cameras.py", "--calib")
    logs = [ros_processes.stop()]
    log = client.stdout + client.stderr + "".join(logs)
    assert client.returncode == 0, log
    assert "camera 'k01' has no calibration" in log, log
    assert "calibration: cameras ['k01', 'k02']" in log, log
    summary = re.search(r"ids \[([^\]]*)\] merged (\d+) ids \[([^\]]*)\]", log)
    assert summary, log
    assert summary.group(1) == "0, 1", log
    assert summary.group(3) == "0, 1", log


def test_ever_new_frame_ids_log_one_line_per_interval(ros_context, log_lines) -> None:
    """A publisher sending a new frame id in every frame used to get one warning per frame."""
    from hiros_core.codec import encode_group
    from hiros_core.model import Skeleton, SkeletonGroup
    from hiros_tracker.node import TrackerNode

    node = TrackerNode()
    node.get_logger = lambda: log_lines
    try:
        for index in range(200):
            frame = f"x{index}_depth_camera_link"
            skeleton = Skeleton.from_positions(np.full((32, 3), 3.0), src_frame=frame)
            node.on_group(encode_group(SkeletonGroup(index + 1, frame, [skeleton])))
    finally:
        node.destroy_node()
    named = [m for _, m in log_lines.lines if "has no calibration" in m]
    assert named == [named[0]]
    assert "'x0' has no calibration (1 camera(s)" in named[0]
    node.absorb_stage()  # (done after each subscription callback; called directly here)
    assert node.counters["dropped.uncalibrated camera"] == 200


def test_the_diagnostics_account_for_every_frame_sent(ros_processes, tmp_path: Path) -> None:
    """received == processed + dropped frames + held on /diagnostics, with detection drops
    apart: the stage's frame and detection drops used to be summed together."""
    pytest.importorskip("hiros_skeleton_msgs.msg")
    calibration = Calibration(
        "k01", "world", {"k01": CameraCalibration(frame_id="k01_depth_camera_link")}
    )
    path = tmp_path / "calibration.yaml"
    save_calibration(calibration, path)
    params = _params("cameras:=[k01]", f"calibration_file:={path}", "camera_qos:=reliable")
    ros_processes.node("hiros_tracker.node", *params)
    client = ros_processes.client(HERE / "diagnostics_client.py")
    log = client.stdout + client.stderr + ros_processes.stop()
    assert client.returncode == 0, log
    found = re.search(r"sent (\d+) diagnostics (\{.*\})", log)
    assert found, log
    sent, counters = int(found.group(1)), json.loads(found.group(2))
    count = {key: int(value) for key, value in counters.items() if str(value).isdigit()}
    frames_dropped = {k: v for k, v in count.items() if k.startswith("dropped.")}
    assert count["received"] == sent, log
    assert count["received"] == count["processed"] + sum(frames_dropped.values()) + count["held"]
    assert frames_dropped == {
        "dropped.duplicate frame": 1,
        "dropped.late frame": 1,
        "dropped.uncalibrated camera": 1,
        "dropped.CodecError": 1,
    }, log
    assert count["dropped_detections.no finite joint"] == 2, log
    assert counters["level"] == 1, log  # WARN: frames were dropped
    assert f"4 of {sent} frame(s) dropped in the last 60 s" in counters["message"], log
    assert float(counters["input_rate_hz"]) > 0, log  # rates and latencies beside the counts
    assert float(counters["latency_ms.max"]) >= float(counters["latency_ms.p50"]) > 0, log
    assert "Traceback" not in log, log

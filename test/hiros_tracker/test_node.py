"""The tracker and merger nodes on live topics: two cameras, two people, calibration file."""

from __future__ import annotations

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

"""The tracker and merger nodes on live topics: two cameras, two people, calibration file."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hiros_core.calibration import Calibration, CameraCalibration, save_calibration

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def _node(module: str, *params: str, env: dict[str, str]) -> subprocess.Popen:
    arguments = [arg for p in params for arg in ("-p", p)]
    return subprocess.Popen(
        [sys.executable, "-c", f"from {module} import main; main()", "--ros-args", *arguments],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def test_tracker_and_merger_nodes_on_live_topics(ros_env: dict[str, str], tmp_path: Path) -> None:
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
    nodes = [
        _node(
            "hiros_tracker.node",
            "cameras:=[k01, k02]",
            f"calibration_file:={path}",
            "min_hits:=3",
            env=ros_env,
        ),
        _node("hiros_merger.node", f"calibration_file:={path}", env=ros_env),
    ]
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "ros_cameras.py")],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    finally:
        logs = []
        for node in nodes:
            node.terminate()
            logs.append(node.communicate(timeout=30)[0])
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


def test_tracker_node_follows_the_calib_node_parameters(ros_env: dict[str, str]) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    nodes = [
        _node("hiros_tracker.node", "cameras:=[k01, k02]", "min_hits:=3", env=ros_env),
        _node("hiros_merger.node", env=ros_env),
    ]
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "ros_cameras.py"), "--calib"],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    finally:
        logs = []
        for node in nodes:
            node.terminate()
            logs.append(node.communicate(timeout=30)[0])
    log = client.stdout + client.stderr + "".join(logs)
    assert client.returncode == 0, log
    assert "camera 'k01' has no calibration" in log, log
    assert "calibration: cameras ['k01', 'k02']" in log, log
    summary = re.search(r"ids \[([^\]]*)\] merged (\d+) ids \[([^\]]*)\]", log)
    assert summary, log
    assert summary.group(1) == "0, 1", log
    assert summary.group(3) == "0, 1", log

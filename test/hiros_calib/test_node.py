"""The calib node on live topics: two cameras on their own clocks, results as parameters."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

HERE = Path(__file__).resolve().parent


@pytest.mark.ros
@pytest.mark.slow
def test_calib_node_publishes_parameters_tf_and_saves(ros_env, tmp_path: Path) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    pytest.importorskip("tf2_msgs.msg")
    pytest.importorskip("std_srvs.srv")
    saved = tmp_path / "calib.yaml"
    params = [
        "camera_names:=[cam0, cam1]",
        "first_estimate_after:=6.0",
        "update_period:=100.0",
        f"save_file:={saved}",
    ]
    node = subprocess.Popen(
        [sys.executable, "-c", "from hiros_calib.node import main; main()", "--ros-args",
         *[arg for p in params for arg in ("-p", p)]],
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )  # fmt: skip
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "ros_publisher.py")],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=150,
            check=False,
        )
    finally:
        node.terminate()
        node_log = node.communicate(timeout=30)[0]
    log = client.stdout + client.stderr + node_log
    assert client.returncode == 0, log
    found = re.search(r"offset (\S+) truth (\S+) tf \[(.*)\] save: (.*)", log)
    assert found, log
    assert float(found.group(1)) == pytest.approx(float(found.group(2)), abs=5e-3), log
    # attached at the root of the driver's tree, never at the frame the driver gives a parent
    assert "'cam1_camera_base'" in found.group(3), log
    assert "depth_camera_link" not in found.group(3), log
    assert found.group(4).startswith("saved ['cam0', 'cam1']"), log
    written = yaml.safe_load(saved.read_text())
    assert set(written["cameras"]) == {"cam0", "cam1"}
    assert "Traceback" not in log, log


def test_result_parameters_are_flat_typed_values() -> None:
    pytest.importorskip("tf2_msgs.msg")
    pytest.importorskip("std_srvs.srv")
    import numpy as np

    from hiros_calib.node import calibration_parameters
    from hiros_core.calibration import Calibration, CameraCalibration

    cam = CameraCalibration(
        frame_id="k02_depth_camera_link",
        time_offset=0.25,
        translation=np.array([1.0, 2.0, 3.0]),
        quality={"inlier_ratio": 0.9, "windows": 6, "joint_residual_m": {"Pelvis": 0.02},
                 "drift_estimated": True, "status": "recalibrating"},
    )  # fmt: skip
    values = calibration_parameters(Calibration("k01", "world", {"k02": cam}))
    assert values["cameras.k02.time_offset"] == 0.25
    assert values["cameras.k02.translation"] == [1.0, 2.0, 3.0]
    assert values["cameras.k02.rotation"] == [0.0, 0.0, 0.0, 1.0]
    assert values["cameras.k02.frame_id"] == "k02_depth_camera_link"
    # numbers become doubles so a parameter keeps its type from one result to the next
    assert values["cameras.k02.quality.windows"] == 6.0
    assert isinstance(values["cameras.k02.quality.windows"], float)
    assert values["cameras.k02.quality.joint_residual_m.Pelvis"] == 0.02
    assert values["cameras.k02.quality.drift_estimated"] is True
    assert values["cameras.k02.quality.status"] == "recalibrating"


@pytest.mark.ros
def test_frames_naming_other_cameras_are_dropped_not_buffered(ros_context) -> None:
    """Ever-new frame ids on a camera topic used to become cameras of their own, each paired
    with all the others in every estimate."""
    import numpy as np

    from hiros_calib.node import CalibNode
    from hiros_core.codec import encode_group
    from hiros_core.model import Skeleton, SkeletonGroup

    def frame(frame_id: str, stamp_ns: int) -> bytes:
        skeleton = Skeleton.from_positions(np.full((32, 3), 3.0), src_frame=frame_id)
        return encode_group(SkeletonGroup(stamp_ns, frame_id, [skeleton]))

    node = CalibNode()
    node._stop.set()  # no estimates in this test
    try:
        node.on_group("k01", frame("k01_depth_camera_link", 1))
        for index in range(50):
            node.on_group("k01", frame(f"x{index}_depth_camera_link", index + 2))
        node.on_group("k01", frame("k02_depth_camera_link", 100))  # a configured camera
        node.on_group("k02", frame("driver_frame", 1))  # a driver's own frame names ...
        node.on_group("k02", frame("driver_frame", 2))  # ... are the camera of that topic
    finally:
        node.destroy_node()
    assert node.counters["dropped.frame_id of another camera"] == 51
    assert sorted(node.live.snapshot()["buffered"].items()) == [("driver_frame", 2), ("k01", 1)]

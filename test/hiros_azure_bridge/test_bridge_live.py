"""The azure_bridge node live over DDS, in two processes, against the offline DriverBridge."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from hiros_azure_bridge import DriverBridge
from hiros_core.codec import decode_group, decode_marker_array

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def _client_module():
    spec = importlib.util.spec_from_file_location("bridge_client", HERE / "bridge_client.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_live_bridge_matches_offline(ros_env):
    pytest.importorskip("hiros_skeleton_msgs.msg")
    client_module = _client_module()
    bridge = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from hiros_azure_bridge import main; main()",
            "--ros-args",
            "-p",
            "cameras:=[k01, k02]",
        ],
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "bridge_client.py")],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    finally:
        bridge.terminate()
        bridge_output, _ = bridge.communicate(timeout=30)
    assert client.returncode == 0, client.stderr + bridge_output
    assert "Traceback" not in bridge_output
    live: dict[str, list] = {}
    for line in client.stdout.splitlines():
        camera, hexdata = line.split()
        live.setdefault(camera, []).append(decode_group(bytes.fromhex(hexdata)))
    for camera in client_module.CAMERAS:
        offline_bridge = DriverBridge()
        offline = [
            group
            for raw in client_module.driver_messages(camera)
            if (group := offline_bridge.update(decode_marker_array(raw))) is not None
        ]
        assert len(offline) == client_module.FRAMES
        assert offline_bridge.drops["nan_position"] == 1
        assert offline_bridge.drops["repeated_stamp"] == 1
        assert offline_bridge.drops["empty_array"] == 1
        assert len(live[camera]) == len(offline)
        assert all(a.same_as(b) for a, b in zip(live[camera], offline, strict=True))
    assert "nan_position" in bridge_output or "dropped input" in bridge_output

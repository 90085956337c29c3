"""The azure_bridge node live over DDS, in two processes, against the offline DriverBridge."""

from __future__ import annotations

import importlib.util
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


def test_live_bridge_matches_offline(ros_processes):
    pytest.importorskip("hiros_skeleton_msgs.msg")
    client_module = _client_module()
    ros_processes.node("hiros_azure_bridge", "-p", "cameras:=[k01, k02]")
    client = ros_processes.client(HERE / "bridge_client.py")
    bridge_output = ros_processes.stop()
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
        assert offline_bridge.drops["empty_array"] == 1  # no arrival time: nothing to stamp
        # live, the empty array is "nobody in view": an empty group between its neighbours
        empty = [i for i, group in enumerate(live[camera]) if not group.skeletons]
        assert len(empty) == 1
        before, nobody, after = live[camera][empty[0] - 1 : empty[0] + 2]
        assert before.stamp_ns < nobody.stamp_ns < after.stamp_ns
        assert nobody.frame_id == before.frame_id
        seen = [group for group in live[camera] if group.skeletons]
        assert len(seen) == len(offline)
        assert all(a.same_as(b) for a, b in zip(seen, offline, strict=True))
    assert "nan_position" in bridge_output or "dropped input" in bridge_output

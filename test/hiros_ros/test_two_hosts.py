"""hiros across two hosts: the bridges on one, their consumers on the other, joined by a veth
pair in network namespaces the test makes itself (two_hosts.sh); the output is what one host
gives (test_bridge_live: the offline bridge's, message for message)."""

from __future__ import annotations

import importlib.util
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hiros_azure_bridge import DriverBridge
from hiros_core.codec import decode_group, decode_marker_array

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent
CLIENT = HERE.parent / "hiros_azure_bridge" / "bridge_client.py"


def _client_module():
    spec = importlib.util.spec_from_file_location("bridge_client", CLIENT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bridges_on_one_host_their_output_on_another(ros_env, tmp_path: Path) -> None:
    if not (shutil.which("unshare") and shutil.which("nsenter") and shutil.which("ip")):
        pytest.skip("unshare, nsenter and ip are needed")
    if subprocess.run(["unshare", "-rn", "true"], check=False).returncode != 0:
        pytest.skip("this kernel does not allow private network namespaces")
    python = shlex.quote(sys.executable)
    bridges = (
        f"exec {python} -c 'from hiros_azure_bridge.node import main; main()' "
        f"--ros-args -p 'cameras:=[k01, k02]' > {tmp_path}/bridges.log 2>&1"
    )
    consumer = f"{python} {shlex.quote(str(CLIENT))}"
    run = subprocess.run(
        ["unshare", "-rn", str(HERE / "two_hosts.sh"), bridges, consumer],
        env=ros_env, capture_output=True, text=True, timeout=180, check=False,
    )  # fmt: skip
    log = run.stderr + (tmp_path / "bridges.log").read_text()
    assert run.returncode == 0, log
    assert "Traceback" not in log
    received: dict[str, list] = {}
    for line in run.stdout.splitlines():
        camera, hexdata = line.split()
        received.setdefault(camera, []).append(decode_group(bytes.fromhex(hexdata)))
    client = _client_module()
    for camera in client.CAMERAS:
        bridge = DriverBridge()
        offline = [
            group
            for raw in client.driver_messages(camera)
            if (group := bridge.update(decode_marker_array(raw))) is not None
        ]
        seen = [group for group in received[camera] if group.skeletons]
        assert len(seen) == len(offline) == client.FRAMES
        assert all(a.same_as(b) for a, b in zip(seen, offline, strict=True))
        assert sum(not group.skeletons for group in received[camera]) == 1  # nobody in view

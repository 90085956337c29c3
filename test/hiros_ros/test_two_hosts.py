"""hiros across hosts on one switch, network namespaces the test makes itself (hosts.sh): camera
PCs with the driver's topics and the bridges, a stage PC with the consumers. The output is what
one host gives: the offline bridge's groups message for message (as test_bridge_live on one
host), and the stages' output as hiros run's, up to message timing (as test_pipeline/test_live
on one host)."""

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
LIVE_TEST = HERE.parent / "hiros_pipeline" / "test_live.py"
RECORDER = HERE.parent / "hiros_pipeline" / "recorder.py"


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _client_module():
    return _module("bridge_client", CLIENT)


def _hosts(env: dict[str, str], *commands: str) -> subprocess.CompletedProcess:
    """Run one shell command per host (the last one's status is the run's)."""
    if not (shutil.which("unshare") and shutil.which("nsenter") and shutil.which("ip")):
        pytest.skip("unshare, nsenter and ip are needed")
    if subprocess.run(["unshare", "-rn", "true"], check=False).returncode != 0:
        pytest.skip("this kernel does not allow private network namespaces")
    return subprocess.run(
        ["unshare", "-rn", str(HERE / "hosts.sh"), *commands],
        env=env, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip


def test_bridges_on_one_host_their_output_on_another(ros_env, tmp_path: Path) -> None:
    python = shlex.quote(sys.executable)
    bridges = (
        f"exec {python} -c 'from hiros_azure_bridge.node import main; main()' "
        f"--ros-args -p 'cameras:=[k01, k02]' > {tmp_path}/bridges.log 2>&1"
    )
    consumer = f"{python} {shlex.quote(str(CLIENT))}"
    run = _hosts(ros_env, bridges, consumer)
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


def test_bridges_on_a_camera_pc_stages_on_another_as_hiros_run(ros_env, tmp_path: Path) -> None:
    from hiros_core.calibration import load_calibration
    from hiros_eval.run import read_run
    from hiros_pipeline import run_recording
    from hiros_sim import SimParams, simulate, write_recording

    scene = tmp_path / "scene"
    params = SimParams(n_cameras=2, n_people=2, duration=8.0, seed=21, enter_leave=False)
    write_recording(simulate(params), scene)
    calibration = scene / "calibration.yaml"
    run_recording(scene / "recording.mcap", load_calibration(calibration), scene / "offline.mcap")
    bin_dir, go, out = Path(sys.prefix) / "bin", tmp_path / "go", tmp_path / "live.bin"
    camera_pc = (  # the bridges, then the recording once the stage PC is listening
        f"{bin_dir}/azure_bridge --ros-args -p 'cameras:=[k01, k02]' 2>{tmp_path}/a.log & "
        f"while [ ! -e {go} ]; do sleep 0.1; done; "
        f"{bin_dir}/hiros play {scene}/recording.mcap --no-clock --rate 0.5 --delay 10 "
        f">>{tmp_path}/a.log 2>&1; wait"
    )
    stage_pc = (  # the composed stages on the bridges' output, and a recorder of /hiros/filter
        f"{bin_dir}/pipeline --ros-args -p 'cameras:=[k01, k02]' -p input:=skeletons "
        f"-p calibration_file:={calibration} 2>{tmp_path}/b.log & "
        f"{sys.executable} {RECORDER} {out} 3 150 pipeline | while read -r line; do "
        f'echo "$line"; case "$line" in "nodes ready"*) touch {go};; esac; done'
    )
    run = _hosts(ros_env, camera_pc, stage_pc)
    logs = run.stdout + run.stderr + (tmp_path / "a.log").read_text()
    logs += (tmp_path / "b.log").read_text()
    assert run.returncode == 0, logs
    assert "nodes ready" in run.stdout, logs
    assert "Traceback" not in logs
    live_test = _module("pipeline_test_live", LIVE_TEST)
    live = live_test._read_recorded(out)
    offline = read_run(scene / "offline.mcap")[0]["filter"]
    assert len(live) > 0.8 * len(offline), logs
    shared, distance = live_test._agreement(live, offline)
    assert shared > 0.6, f"only {shared:.0%} of the offline output stamps were produced"
    assert distance < 0.02, f"people differ by {distance * 100:.1f} cm (median)"

"""Separate nodes, the composed pipeline node and ``hiros run`` agree on the same recording.

The recording is replayed over DDS (``hiros play``); live delivery may group frames differently
in the tracker's out-of-order window, so agreement is checked up to message timing: most output
stamps are shared, and where they are, the people are in the same places.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hiros_core.calibration import load_calibration
from hiros_core.codec import decode_group
from hiros_eval.run import read_run
from hiros_pipeline import run_recording
from hiros_sim import SimParams, simulate, write_recording

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent
BIN = Path(sys.prefix) / "bin"


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("live")
    params = SimParams(n_cameras=2, n_people=2, duration=8.0, seed=21, enter_leave=False)
    write_recording(simulate(params), folder)
    run_recording(
        folder / "recording.mcap",
        load_calibration(folder / "calibration.yaml"),
        folder / "offline.mcap",
    )
    return folder


def _read_recorded(path: Path) -> list:
    """Groups as received, each with ``arrival`` (wall-clock seconds) set on it."""
    data, groups = path.read_bytes(), []
    offset = 0
    while offset < len(data):
        arrival, size = struct.unpack_from("<dI", data, offset)
        group = decode_group(data[offset + 12 : offset + 12 + size])
        group.arrival = arrival
        groups.append(group)
        offset += 12 + size
    return groups


def _start_recorder(
    out: Path, idle: float, timeout: float, env: dict[str, str], nodes: list[str]
) -> subprocess.Popen:
    """The filter output recorder (recorder.py), once it and every one of ``nodes`` is up."""
    command = [sys.executable, str(HERE / "recorder.py"), str(out), str(idle), str(timeout)]
    recorder = subprocess.Popen([*command, ",".join(nodes)], env=env, stdout=subprocess.PIPE,
                                text=True)  # fmt: skip
    assert recorder.stdout is not None
    assert "recorder ready" in recorder.stdout.readline()
    started = recorder.stdout.readline()
    assert "nodes ready" in started, started
    time.sleep(1.0)  # the nodes' own discovery of each other
    return recorder


def _node_names(commands: list[list[str]]) -> list[str]:
    """The ROS node name of each command (each executable's default name is its own)."""
    return [Path(command[0]).name for command in commands]


def _play_command(scene: Path, rate: float) -> list[str]:
    """``hiros play`` of the scene onto live topics after 10 s, without /clock."""
    recording = str(scene / "recording.mcap")
    return [
        str(BIN / "hiros"),
        "play",
        recording,
        "--delay",
        "10",
        "--no-clock",
        "--rate",
        str(rate),
    ]


def _live_run(scene: Path, commands: list[list[str]], env: dict[str, str], out: Path) -> list:
    nodes = [
        subprocess.Popen(c, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for c in commands
    ]
    try:
        recorder = _start_recorder(out, 3.0, 90.0, env, _node_names(commands))
        play = subprocess.run(
            # half speed: five node processes share two cores with the player
            _play_command(scene, 0.5),
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        assert play.returncode == 0, play.stderr
        recorder.wait(timeout=120)
    finally:
        for node in nodes:
            node.terminate()
        errors = [node.communicate(timeout=30)[1] for node in nodes]
    assert not any("Traceback" in e for e in errors), errors
    return _read_recorded(out)


def _agreement(live: list, offline: list) -> tuple[float, float]:
    by_stamp = {g.stamp_ns: g for g in offline}
    shared, distances = 0, []
    for group in live:
        match = by_stamp.get(group.stamp_ns)
        if match is None:
            continue
        shared += 1
        ours = {s.id: s.positions for s in group.skeletons}
        for skeleton in match.skeletons:
            if skeleton.id in ours:
                distances.append(
                    np.nanmean(np.linalg.norm(ours[skeleton.id] - skeleton.positions, axis=1))
                )
    return shared / max(len(offline), 1), float(np.median(distances)) if distances else np.inf


def _commands(mode: str, calibration: Path) -> list[list[str]]:
    cameras = "cameras:=[k01, k02]"
    calib = f"calibration_file:={calibration}"
    if mode == "composed":
        return [
            [str(BIN / "pipeline"), "--ros-args", "-p", cameras, "-p", calib, "-p", "input:=driver"]
        ]
    return [
        [str(BIN / "azure_bridge"), "--ros-args", "-p", cameras],
        [str(BIN / "tracker"), "--ros-args", "-p", cameras, "-p", calib],
        [str(BIN / "merger"), "--ros-args", "-p", calib],
        [str(BIN / "optimizer")],
        [str(BIN / "filter")],
    ]


@pytest.mark.parametrize("mode", ["composed", "nodes"])
def test_live_pipeline_agrees_with_hiros_run(
    mode: str, scene: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    outputs, _ = read_run(scene / "offline.mcap")
    offline = outputs["filter"]
    live = _live_run(
        scene, _commands(mode, scene / "calibration.yaml"), ros_env, tmp_path / "live.bin"
    )
    assert len(live) > 0.8 * len(offline)
    shared, distance = _agreement(live, offline)
    assert shared > 0.6, f"only {shared:.0%} of the offline output stamps were produced live"
    assert distance < 0.02, (
        f"people differ by {distance * 100:.1f} cm (median) between live and offline"
    )


def test_a_killed_node_restarts_and_the_pipeline_resumes(
    scene: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    calibration = scene / "calibration.yaml"
    commands = _commands("nodes", calibration)
    merger_command = commands[2]
    nodes = [subprocess.Popen(c, env=ros_env, stdout=subprocess.DEVNULL) for c in commands]
    out = tmp_path / "live.bin"
    try:
        recorder = _start_recorder(out, 12.0, 120.0, ros_env, _node_names(commands))
        play = subprocess.Popen(_play_command(scene, 0.4), env=ros_env, stdout=subprocess.DEVNULL)
        assert recorder.stdout is not None
        assert "first output" in recorder.stdout.readline()
        time.sleep(1.5)
        killed_wall = time.time()
        nodes[2].kill()  # the merger dies mid-stream
        nodes[2].wait(timeout=10)
        restarted_wall = time.time()
        nodes[2] = subprocess.Popen(merger_command, env=ros_env, stdout=subprocess.DEVNULL)
        assert play.wait(timeout=120) == 0
        recorder.wait(timeout=120)
    finally:
        for node in nodes:
            node.terminate()
            node.wait(timeout=30)
    arrivals = np.array([g.arrival for g in _read_recorded(out)])
    before = arrivals[arrivals < killed_wall]
    after = arrivals[arrivals > restarted_wall]
    assert before.size > 10, "no output before the merger was killed"
    assert after.size > 10, "the pipeline did not resume after the merger was restarted"
    assert not ((arrivals > killed_wall + 0.2) & (arrivals < restarted_wall)).any()

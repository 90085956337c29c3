"""hiros play: the schedule and options offline, then a live replay in two processes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hiros_cli.commands.play import latched, parse_remaps, playback_schedule
from hiros_core.codec import encode_group
from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import SKELETON_GROUP, RecordingWriter

HERE = Path(__file__).resolve().parent
T0 = 1_700_000_000_000_000_000


def test_schedule_rate_and_start():
    times = [T0, T0 + 500_000_000, T0 + 1_000_000_000, T0 + 3_000_000_000]
    assert list(playback_schedule(times)) == [
        (times[0], 0.0),
        (times[1], 0.5),
        (times[2], 1.0),
        (times[3], 3.0),
    ]
    assert [w for _, w in playback_schedule(times, rate=2.0)] == [0.0, 0.25, 0.5, 1.5]
    assert list(playback_schedule(times, start=0.7)) == [(times[2], 0.0), (times[3], 2.0)]
    with pytest.raises(ConfigError, match="rate"):
        list(playback_schedule(times, rate=0))


def test_remaps():
    assert parse_remaps(["/a:=/b", "/c/d:=/e"]) == {"/a": "/b", "/c/d": "/e"}
    with pytest.raises(ConfigError, match="remap"):
        parse_remaps(["/a=/b"])


def _group(index: int, camera: str) -> SkeletonGroup:
    stamp = T0 + index * 50_000_000
    frame = f"{camera}_depth_camera_link"
    positions = np.full((32, 3), 0.01 * index) + np.arange(32)[:, None]
    skeleton = Skeleton.from_positions(
        positions, AZURE_KINECT, skeleton_id=3, src_time_ns=stamp - 7, src_frame=frame
    )
    return SkeletonGroup(stamp, frame, [skeleton])


@pytest.mark.ros
@pytest.mark.slow
def test_live_replay_keeps_bytes_and_stamps(tmp_path, ros_env):
    pytest.importorskip("hiros_skeleton_msgs.msg")
    recording = tmp_path / "take.mcap"
    sent = {"/k01/skeletons": [], "/k02/skeletons": []}
    with RecordingWriter(recording) as writer:
        for index in range(20):
            for topic, camera in (("/k01/skeletons", "k01"), ("/k02/skeletons", "k02")):
                raw = encode_group(_group(index, camera))
                writer.write(
                    topic, "hiros_skeleton_msgs/msg/SkeletonGroup", raw, T0 + index * 50_000_000
                )
                sent[topic].append(raw)
    listener = subprocess.Popen(
        [
            sys.executable,
            str(HERE / "play_listener.py"),
            "15",
            "/cam_a/skeletons",
            "/k02/skeletons",
        ],
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert listener.stdout.readline().strip() == "ready"
    play = subprocess.run(
        [
            sys.executable,
            "-m",
            "hiros_cli.main",
            "play",
            str(recording),
            "--rate",
            "4",
            "--start",
            "0.25",
            "--topics",
            "/k01/skeletons",
            "--remap",
            "/k01/skeletons:=/cam_a/skeletons",
            "--delay",
            "30",
        ],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    out, _ = listener.communicate(timeout=90)
    assert play.returncode == 0, play.stderr
    assert "/cam_a/skeletons: 15 messages" in play.stdout
    lines = out.splitlines()
    received = [bytes.fromhex(line.split()[1]) for line in lines if line.startswith("/cam_a")]
    assert not any(line.startswith("/k02") for line in lines)  # not selected
    assert received == sent["/k01/skeletons"][5:]  # 0.25 s skipped = 5 frames; bytes unchanged
    _, count, first, last = next(line for line in lines if line.startswith("clock")).split()
    assert int(count) >= 15
    assert T0 + 5 * 50_000_000 <= int(first) <= int(last) <= T0 + 19 * 50_000_000


def test_case6_play_imports_no_module_a_schema_names() -> None:
    """Issue 21 case 6: a schema ``this/msg/X`` printed the Zen of Python."""
    from hiros_cli.commands.play import message_class

    for msgtype in ("this/msg/X", "antigravity/msg/X", "os/msg/X", "hiros_cli/msg/main"):
        package = msgtype.split("/")[0]
        was_imported = package in sys.modules
        assert message_class(msgtype) == (None, "unknown_type")
        assert (package in sys.modules) == was_imported
    assert message_class("std_msgs/msg/__builtins__") == (None, "unknown_type")
    assert message_class("std_msgs/msg/NoSuchType") == (None, "unknown_type")
    group, reason = message_class("hiros_skeleton_msgs/msg/SkeletonGroup")
    assert reason == ""
    assert group.__name__ == "SkeletonGroup"


def test_the_topics_hiros_latches_are_played_latched():
    assert latched("/hiros/calibration")
    assert latched("/tf_static")
    assert not latched("/k01/skeletons")
    assert not latched("/hiros/filter")


@pytest.mark.ros
@pytest.mark.slow
def test_a_late_subscriber_gets_the_played_calibration(tmp_path, ros_env):
    """``/hiros/calibration`` is logged once, at the start: a node subscribing after it went
    out gets it all the same, as from the live graph."""
    pytest.importorskip("hiros_skeleton_msgs.msg")
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    recording = tmp_path / "take.mcap"
    calibration = "reference: k01"
    with RecordingWriter(recording) as writer:
        writer.write("/hiros/calibration", "std_msgs/msg/String",
                     serialize_message(String(data=calibration)), T0)  # fmt: skip
        for index in range(60):
            raw = encode_group(_group(index, "k01"))
            writer.write("/k01/skeletons", SKELETON_GROUP, raw, T0 + index * 50_000_000)
    listener = subprocess.Popen(
        [sys.executable, str(HERE / "play_late_listener.py"), "10", "/k01/skeletons"],
        env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert listener.stdout.readline().strip() == "ready"
    play = subprocess.run(
        [sys.executable, "-m", "hiros_cli.main", "play", str(recording), "--delay", "3"],
        env=ros_env, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    out, err = listener.communicate(timeout=90)
    assert play.returncode == 0, play.stderr
    assert "/hiros/calibration: 1 messages" in play.stdout
    frames = int(next(line for line in out.splitlines() if line.startswith("frames")).split()[-1])
    assert frames >= 10, err  # it subscribed after the calibration had gone out
    assert f"calibration {calibration}" in out.splitlines(), out + err

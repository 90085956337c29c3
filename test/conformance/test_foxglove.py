"""Every kind of file hiros writes opens in Foxglove's own libraries and in the ``mcap`` reader.

The files: a ``hiros simulate`` recording, ``hiros convert`` outputs (a driver-topic rosbag2
folder and a SkeletonGroup ``.mcap``) and a ``hiros run`` output. Foxglove's side is
``read_mcap.cjs`` on the npm packages pinned in ``package.json`` (``@mcap/core``,
``@foxglove/rosmsg`` in ROS 2 mode, ``@foxglove/rosmsg2-serialization``), installed by this
module into ``test/.npm`` (git-ignored) once per version; Python's side is ``mcap`` with
``mcap_ros2``'s decoder. Both must parse every schema and decode every message, agree on what
they decoded, and see a timeline within the data.
"""

from __future__ import annotations

import fcntl
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hiros_cli.main import main
from hiros_core.layouts import AZURE_KINECT

HERE = Path(__file__).parent
NPM_DIR = HERE.parent / ".npm"
DURATION = 4.0  # seconds simulated


def _npm_modules() -> Path:
    """``test/.npm/node_modules`` with the pinned packages, installed when missing or changed."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node and npm are not installed: Foxglove's libraries cannot run here")
    NPM_DIR.mkdir(exist_ok=True)
    wanted = (HERE / "package.json").read_text()
    with (NPM_DIR / ".lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one install at a time (parallel test processes)
        installed = NPM_DIR / "package.json"
        modules = NPM_DIR / "node_modules"
        if not modules.is_dir() or not installed.is_file() or installed.read_text() != wanted:
            installed.write_text(wanted)
            subprocess.run(
                [npm, "install", "--no-audit", "--no-fund", "--no-package-lock"],
                cwd=NPM_DIR, check=True, capture_output=True, timeout=300,
            )  # fmt: skip
    return modules


def _generic_csv(path: Path) -> Path:
    """Two cameras, one person, 20 frames at 30 Hz, in the generic CSV."""
    rng = np.random.default_rng(3)
    rows = ["camera,stamp_ns,body_id,joint,x,y,z"]
    pose = rng.normal([0.0, 0.0, 2.5], 0.3, size=(AZURE_KINECT.n_joints, 3))
    for frame in range(20):
        for camera in ("k01", "k02"):
            stamp = 1_700_000_000_000_000_000 + frame * 33_333_333
            for joint, (x, y, z) in enumerate(pose + 0.01 * frame):
                rows.append(f"{camera},{stamp},1,{joint},{x:.4f},{y:.4f},{z:.4f}")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The kind of file -> its MCAP, each made by the ``hiros`` command as a user would."""
    root = tmp_path_factory.mktemp("conformance")
    sim = root / "sim"
    commands = [
        ["simulate", "--out", str(sim), "--duration", str(DURATION), "--people", "1"],
        ["run", str(sim / "recording.mcap"), "--calibration", str(sim / "calibration.yaml"),
         "--out", str(root / "run.mcap")],
        ["convert", str(_generic_csv(root / "take.csv")), "--out", str(root / "driver_bag")],
        ["convert", str(root / "take.csv"), "--skeleton-groups",
         "--out", str(root / "groups.mcap")],
    ]  # fmt: skip
    for command in commands:
        assert main(command) == 0, command
    return {
        "simulate": sim / "recording.mcap",
        "run": root / "run.mcap",
        "convert (driver topics, rosbag2 folder)": root / "driver_bag" / "driver_bag_0.mcap",
        "convert (SkeletonGroup)": root / "groups.mcap",
    }


@pytest.fixture(scope="module")
def foxglove(files: dict[str, Path]) -> dict[str, dict]:
    """What Foxglove's libraries decoded, by kind of file."""
    modules = _npm_modules()
    paths = [str(p) for p in files.values()]
    done = subprocess.run(
        ["node", str(HERE / "read_mcap.cjs"), str(modules), *paths],
        check=True, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    report = json.loads(done.stdout)
    return {kind: report[str(path)] for kind, path in files.items()}


def _python_counts(path: Path) -> dict[str, tuple[int, int]]:
    """Per topic: messages decoded by ``mcap_ros2``, and the skeletons, markers, transforms or
    strings in them."""
    counts: dict[str, tuple[int, int]] = {}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, message in reader.iter_decoded_messages():
            items = (
                len(message.skeletons) if hasattr(message, "skeletons")
                else len(message.markers) if hasattr(message, "markers")
                else len(message.transforms) if hasattr(message, "transforms")
                else int(bool(message.data))
            )  # fmt: skip
            messages, total = counts.get(channel.topic, (0, 0))
            counts[channel.topic] = (messages + 1, total + items)
    return counts


KINDS = ["simulate", "run", "convert (driver topics, rosbag2 folder)", "convert (SkeletonGroup)"]


@pytest.mark.parametrize("kind", KINDS)
def test_foxglove_decodes_every_message(foxglove: dict[str, dict], kind: str) -> None:
    report = foxglove[kind]
    assert "error" not in report, report.get("error")
    assert report["profile"] == "ros2"
    assert report["topics"]
    for topic, seen in report["topics"].items():
        assert seen["errors"] == [], (topic, seen["errors"])
        assert seen["messages"] > 0, topic
        assert seen["decoded"] == seen["messages"], topic
        assert seen["trailing"] == 0, topic  # every byte of every message belongs to a field
        assert seen["encoding"] == "cdr/ros2msg"
        assert set(seen["channel_metadata"]) == {"offered_qos_profiles", "topic_type_hash"}
        assert seen["channel_metadata"]["topic_type_hash"].startswith("RIHS01_")
    assert {"name": "rosbag2", "keys": ["ROS_DISTRO", "serialized_metadata"]} in report["metadata"]


@pytest.mark.parametrize("kind", KINDS)
def test_python_mcap_agrees_with_foxglove(
    files: dict[str, Path], foxglove: dict[str, dict], kind: str
) -> None:
    ours = _python_counts(files[kind])
    theirs = {t: (s["decoded"], s["items"]) for t, s in foxglove[kind]["topics"].items()}
    assert ours == theirs


@pytest.mark.parametrize("kind", KINDS)
def test_timeline_stays_within_the_data(foxglove: dict[str, dict], kind: str) -> None:
    """No message far from the others (the calibration used to be logged at 0: 54 years)."""
    report = foxglove[kind]
    start, end = int(report["message_start_time"]), int(report["message_end_time"])
    assert 0 < end - start <= (DURATION + 1.0) * 1e9
    for seen in report["topics"].values():
        assert start <= int(seen["first_log_time"]) <= int(seen["last_log_time"]) <= end


def test_run_output_calibration_comes_with_the_first_frames(foxglove: dict[str, dict]) -> None:
    topics = foxglove["run"]["topics"]
    calibration = int(topics["/hiros/calibration"]["first_log_time"])
    first = min(int(s["first_log_time"]) for s in topics.values())
    assert calibration - first < 0.1e9
    assert (
        topics["/hiros/calibration"]["channel_metadata"]["offered_qos_profiles"].count(
            "transient_local"
        )
        == 1
    )

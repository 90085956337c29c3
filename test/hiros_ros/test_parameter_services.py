"""A running node's parameters through its parameter services, as a client sees them:
``hiros param`` and ``hiros topic`` (rclpy clients) against real node processes.

Also a parameter file written the way Hi-ROS writes its own (node ``/hiros/skeleton_*``, Hi-ROS's
names and values) drives hiros's tracker and filter."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

HIROS_STYLE = """\
/hiros/skeleton_tracker:
  ros__parameters:
    input_topics: [/cam_left/skeletons, /cam_right/skeletons]
    output_topic: /hiros/tracker
    fixed_delay: 0.08
    min_skeleton_confidence: -1.0
    max_delta_t: 0.0
    velocity_weight: 0.0
/hiros/skeleton_filter:
  ros__parameters:
    input_topic: /hiros/optimizer
    output_topic: /hiros/filter
    filter: statespace
    cutoff_frequency: 4.0
"""


def hiros(env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    code = "import sys; from hiros_cli.main import main; sys.exit(main(sys.argv[1:]))"
    command = [sys.executable, "-c", code, *args]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=60, check=False)


def wait_for(env: dict[str, str], node: str) -> None:
    deadline = time.monotonic() + 120
    while hiros(env, "param", "list", node, "--timeout", "2").returncode != 0:
        assert time.monotonic() < deadline, f"{node} did not come up"


def test_describe_set_refuse_get_and_the_topic_tools(ros_processes) -> None:
    ros_processes.node("hiros_filter.node")
    env = ros_processes.env
    wait_for(env, "/filter")
    described = hiros(env, "param", "describe", "/filter", "cutoff_frequency", "input_topic")
    assert described.returncode == 0, described.stderr
    assert "Hz, -3 dB point of the low-pass." in described.stdout
    assert "range: 0 .. any" in described.stdout
    assert "applied while running" in described.stdout
    assert described.stdout.split("input_topic (string)")[1].count("read-only") == 1
    refusals = {
        ("cutoff_frequency", "-5"): "out of range",
        ("filter", "nonsense"): "read-only parameter: filter",
        ("input_topic", "/elsewhere"): "read-only parameter: input_topic",
        ("cutoff_frequency", "0"): "cutoff_frequency must be > 0",
    }
    for (name, value), reason in refusals.items():
        refused = hiros(env, "param", "set", "/filter", name, value)
        assert refused.returncode == 1, refused.stdout
        assert reason in refused.stderr, refused.stderr
    applied = hiros(env, "param", "set", "/filter", "cutoff_frequency", "4")
    assert applied.returncode == 0, applied.stderr
    got = hiros(env, "param", "get", "/filter", "cutoff_frequency", "input_topic", "filter")
    assert got.stdout.splitlines() == [
        "cutoff_frequency: 4.0",
        "input_topic: /hiros/optimizer",
        "filter: kalman",
    ]
    # a new process discovers the graph afresh: give a loaded machine time (2 s by default)
    listed = hiros(env, "topic", "list", "--wait", "10")
    assert "/diagnostics [diagnostic_msgs/msg/DiagnosticArray]" in listed.stdout
    echoed = hiros(env, "topic", "echo", "/diagnostics", "-n", "1")
    assert "name: /filter" in echoed.stdout, echoed.stderr
    rate = hiros(env, "topic", "hz", "/diagnostics", "--duration", "3.5")
    last = rate.stdout.splitlines()[-1]
    assert last.startswith("average rate: 1.0") or last.startswith("average rate: 0.99"), last
    output = ros_processes.stop()
    assert "applied cutoff_frequency = 4.0" in output
    assert "Traceback" not in output


def test_a_hiros_style_parameter_file_drives_our_nodes(ros_processes, tmp_path: Path) -> None:
    params = tmp_path / "hiros_params.yaml"
    params.write_text(HIROS_STYLE)
    for module, name in (("hiros_tracker.node", "skeleton_tracker"),
                         ("hiros_filter.node", "skeleton_filter")):  # fmt: skip
        ros_processes.node(
            module, "-r", f"__node:={name}", "-r", "__ns:=/hiros", "--params-file", str(params)
        )
    env = ros_processes.env
    wait_for(env, "/hiros/skeleton_tracker")
    wait_for(env, "/hiros/skeleton_filter")
    tracker = hiros(env, "param", "get", "/hiros/skeleton_tracker", "max_delay", "input_topics")
    assert tracker.stdout.splitlines() == [
        "max_delay: 0.08",
        "input_topics: [/cam_left/skeletons, /cam_right/skeletons]",
    ], tracker.stderr
    nodes_filter = hiros(
        env, "param", "get", "/hiros/skeleton_filter", "filter", "cutoff_frequency"
    )
    assert nodes_filter.stdout.splitlines() == ["filter: statespace", "cutoff_frequency: 4.0"]
    output = ros_processes.stop()
    assert "['/cam_left/skeletons', '/cam_right/skeletons'] -> Tracker" in output
    assert "Traceback" not in output

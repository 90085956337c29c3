"""The launch files, as far as this machine allows: ``launch`` is not on PyPI.

What a launch starts is ``hiros_ros.launch_plan``'s list of nodes; the launch files are read
with stand-ins of ``launch``/``launch_ros`` that record the actions they are given; and the
nodes' own command lines (``NodeSpec.command``, what ``ros2 launch`` would run) are started
for real, and asked for their parameters and topics.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
import types
from pathlib import Path
from typing import Any

import pytest

from hiros_ros.launch_description import PIPELINE_ARGUMENTS
from hiros_ros.launch_plan import NODES, node_plan, parse_cameras

REPO = Path(__file__).resolve().parents[2]


def by_name(specs):
    return {spec.name: spec for spec in specs}


def test_the_cameras_reach_every_node_that_needs_them() -> None:
    separate = by_name(node_plan(["a1", "b2"]))
    assert list(separate) == list(NODES)
    assert separate["azure_bridge"].parameters["cameras"] == ["a1", "b2"]
    assert separate["calib"].parameters["camera_names"] == ["a1", "b2"]
    assert separate["tracker"].parameters["cameras"] == ["a1", "b2"]
    composed = by_name(node_plan(["a1", "b2"], composed=True))
    assert list(composed) == ["calib", "pipeline", "visualizer"]
    assert composed["pipeline"].parameters["cameras"] == ["a1", "b2"]
    assert "azure_bridge" not in by_name(node_plan(["a1"], camera_input="skeletons"))


def test_sim_time_calibration_and_namespace_reach_every_node() -> None:
    specs = node_plan(["k01"], namespace="lab", use_sim_time=True, calibration_file="c.yaml")
    assert all(spec.parameters["use_sim_time"] is True for spec in specs)
    named = by_name(specs)
    for name in ("calib", "tracker", "merger"):
        assert named[name].parameters["calibration_file"] == "c.yaml"
    assert named["tracker"].parameters["calib_node"] == "/lab/calib"
    remaps = dict(named["filter"].remappings)
    assert remaps["/hiros/optimizer"] == "/lab/hiros/optimizer"
    assert remaps["/k01/body_tracking_data"] == "/lab/k01/body_tracking_data"
    assert remaps["/hiros/filter/markers"] == "/lab/hiros/filter/markers"
    assert "/tf_static" not in remaps
    from hiros_optimizer.node import HIROS_SERVICES

    assert all(remaps[name] == f"/lab{name}" for name in HIROS_SERVICES)
    assert node_plan(["k01"])[0].remappings == []
    arguments = named["tracker"].ros_arguments("/lab")
    assert arguments[:5] == ["--ros-args", "-r", "__node:=tracker", "-r", "__ns:=/lab"]
    assert "cameras:=[k01]" in arguments


def test_camera_arguments_are_read_or_refused() -> None:
    assert parse_cameras("[k01, k02]") == ["k01", "k02"]
    assert parse_cameras("k01,k02") == ["k01", "k02"]
    with pytest.raises(Exception, match="no camera name"):
        parse_cameras("[]")


class Recorded:
    """A launch action or substitution: its class name and arguments."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs

    def perform(self, context: Any) -> str:  # LaunchConfiguration
        return context.launch_configurations[self.args[0]]


@pytest.fixture
def launch_stand_ins(monkeypatch: pytest.MonkeyPatch) -> None:
    """``launch`` and ``launch_ros`` modules whose classes record how they were made."""
    modules = {}
    for name, classes in {
        "launch": ["LaunchDescription"],
        "launch.actions": ["DeclareLaunchArgument", "OpaqueFunction"],
        "launch.substitutions": ["LaunchConfiguration"],
        "launch_ros": [],
        "launch_ros.actions": ["Node"],
    }.items():
        module = types.ModuleType(name)
        for class_name in classes:
            setattr(module, class_name, type(class_name, (Recorded,), {}))
        modules[name] = module
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)


def load(path: Path) -> types.ModuleType:
    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_pipeline_launch_file_declares_its_arguments_and_makes_the_plan(
    launch_stand_ins,
) -> None:
    description = load(REPO / "launch" / "pipeline.launch.py").generate_launch_description()
    *declared, opaque = description.args[0]
    assert [d.args[0] for d in declared] == list(PIPELINE_ARGUMENTS)
    assert all(d.kwargs["description"] for d in declared)
    values = {name: default for name, (default, _) in PIPELINE_ARGUMENTS.items()}
    values |= {"cameras": "[left, right]", "namespace": "lab", "use_sim_time": "true",
               "params_file": "mine.yaml"}  # fmt: skip
    context = types.SimpleNamespace(launch_configurations=values)
    nodes = opaque.kwargs["function"](context)
    plan = node_plan(["left", "right"], namespace="lab", use_sim_time=True)
    assert [node.kwargs["executable"] for node in nodes] == [spec.executable for spec in plan]
    for node, spec in zip(nodes, plan, strict=True):
        assert node.kwargs["parameters"] == ["mine.yaml", spec.parameters]
        assert node.kwargs["remappings"] == spec.remappings
        assert node.kwargs["namespace"] == "lab"
    values |= {"composed": "true", "rviz": "true", "params_file": ""}
    nodes = opaque.kwargs["function"](context)
    assert [node.kwargs["executable"] for node in nodes] == [
        "calib", "pipeline", "visualizer", "rviz2"
    ]  # fmt: skip
    rviz_file = Path(nodes[-1].kwargs["arguments"][1])
    assert rviz_file.is_file()
    assert nodes[-1].kwargs["package"] == "rviz2"


@pytest.mark.parametrize("node", [*NODES])
def test_each_node_has_a_hiros_style_launch_file(launch_stand_ins, node: str) -> None:
    description = load(REPO / "launch" / f"{node}.launch.py").generate_launch_description()
    *declared, action = description.args[0]
    defaults = {d.args[0]: d.kwargs["default_value"] for d in declared}
    assert Path(defaults["params_file"]).is_file()
    assert Path(defaults["params_file"]).name == f"{node}.yaml"
    assert action.kwargs["executable"] == node
    assert action.kwargs["package"] == "hiros"


def hiros(env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    code = "import sys; from hiros_cli.main import main; sys.exit(main(sys.argv[1:]))"
    command = [sys.executable, "-c", code, *args]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=60, check=False)


@pytest.mark.ros
@pytest.mark.slow
def test_the_planned_commands_start_nodes_with_the_launch_s_values(ros_processes) -> None:
    plan = by_name(node_plan(["left", "right"], namespace="lab", use_sim_time=True))
    for name in ("azure_bridge", "calib", "tracker"):
        ros_processes.command(plan[name].command("/lab"))
    env = ros_processes.env
    deadline = time.monotonic() + 120
    while hiros(env, "param", "list", "/lab/tracker", "--timeout", "2").returncode != 0:
        assert time.monotonic() < deadline, "the tracker did not come up"
    got = hiros(env, "param", "get", "/lab/tracker", "cameras", "use_sim_time", "calib_node")
    assert got.stdout.splitlines() == [
        "cameras: [left, right]", "use_sim_time: true", "calib_node: /lab/calib"
    ], got.stderr  # fmt: skip
    calib = hiros(env, "param", "get", "/lab/calib", "camera_names")
    assert calib.stdout.strip() == "camera_names: [left, right]", calib.stderr
    topics = hiros(env, "topic", "list", "--wait", "10").stdout  # a loaded machine discovers slowly
    for topic in ("/lab/left/skeletons", "/lab/right/skeletons", "/lab/hiros/tracker"):
        assert topic in topics, topics
    output = ros_processes.stop()
    assert "['/left/skeletons', '/right/skeletons'] -> Tracker" in output  # remapped by ROS
    assert "Traceback" not in output

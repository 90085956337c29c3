"""Which nodes a hiros launch starts, with which parameters and remappings, without ``launch``.

The launch files (``launch/*.launch.py``) turn a ``NodeSpec`` list into ``launch_ros`` Node
actions; the same list gives each node's command line (``NodeSpec.command``), so that what a
launch would start can be run and tested where ``launch`` is not installed (it is not on PyPI).

One launch's arguments reach every node that needs them: ``cameras`` (the bridge's and the
tracker's ``cameras``, calib's ``camera_names``, the composed pipeline's ``cameras``),
``use_sim_time`` (every node: with ``hiros play``'s /clock), ``calibration_file`` and the
namespace. hiros's topics are absolute (``/hiros/tracker``, ``/k01/skeletons``), which a ROS
namespace leaves alone; so under a namespace every node gets the same remappings, each topic
of the pipeline to its namespaced name (``/hiros/tracker`` -> ``/lab/hiros/tracker``), and
follows ``<namespace>/calib``. ``/tf_static`` and ``/diagnostics`` stay global, as ROS tools
expect them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import yaml

from hiros_core.errors import ConfigError

__all__ = ["NODES", "STAGE_TOPICS", "NodeSpec", "node_plan", "parse_cameras"]

NODES = ("azure_bridge", "calib", "tracker", "merger", "optimizer", "filter", "visualizer")
"""The separate nodes of a full pipeline, in data-flow order."""

STAGE_TOPICS = ("/hiros/tracker", "/hiros/merger", "/hiros/optimizer", "/hiros/filter")

HIROS_SERVICES = ("/hiros/calibrate", "/hiros/change_id")
"""The optimizer's services at Hi-ROS's names (``hiros_optimizer.node.HIROS_SERVICES``)."""


@dataclasses.dataclass
class NodeSpec:
    """One node of a launch.

    Attributes:
        executable: ``ros2 run hiros <executable>`` (or rviz2's).
        name: node name.
        parameters: values set by the launch (they win over ``params_file``).
        remappings: ``(from, to)`` topic names.
        package: the ROS package of the executable.
        arguments: command-line arguments before ``--ros-args`` (rviz2's ``-d FILE``).

    """

    executable: str
    name: str
    parameters: dict[str, Any]
    remappings: list[tuple[str, str]]
    package: str = "hiros"
    arguments: list[str] = dataclasses.field(default_factory=list)

    def ros_arguments(self, namespace: str = "", params_file: str = "") -> list[str]:
        """``--ros-args`` as ``launch_ros`` would pass them (file first, then the values)."""
        arguments = ["--ros-args", "-r", f"__node:={self.name}"]
        if namespace:
            arguments += ["-r", f"__ns:={namespace}"]
        for source, target in self.remappings:
            arguments += ["-r", f"{source}:={target}"]
        if params_file:
            arguments += ["--params-file", params_file]
        for name, value in self.parameters.items():
            arguments += ["-p", f"{name}:={_yaml_value(value)}"]
        return arguments

    def command(self, namespace: str = "", params_file: str = "") -> list[str]:
        """The process ``ros2 launch`` would start: ``<prefix>/lib/<package>/<executable>``."""
        from ament_index_python.packages import get_package_prefix

        executable = Path(get_package_prefix(self.package)) / "lib" / self.package
        return [
            str(executable / self.executable),
            *self.arguments,
            *self.ros_arguments(namespace, params_file),
        ]


def _yaml_value(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("\n...")


def parse_cameras(text: str) -> list[str]:
    """``[k01, k02]`` or ``k01,k02`` (a launch argument) -> camera names."""
    value = yaml.safe_load(text) if text.strip().startswith("[") else text.split(",")
    cameras = [str(c).strip() for c in value or [] if str(c).strip()]
    if not cameras:
        msg = f"cameras: no camera name in {text!r} (give e.g. '[k01, k02]')"
        raise ConfigError(msg)
    return cameras


def _remappings(namespace: str, cameras: list[str]) -> list[tuple[str, str]]:
    """Every pipeline topic to its name under ``namespace`` (none without one)."""
    if not namespace:
        return []
    kinds = ("body_tracking_data", "skeletons")
    topics = [
        *(f"/{camera}/{kind}" for camera in cameras for kind in kinds),
        *STAGE_TOPICS,
        *(f"{topic}/markers" for topic in STAGE_TOPICS),
        *HIROS_SERVICES,
    ]
    return [(topic, f"{namespace}{topic}") for topic in topics]


def node_plan(
    cameras: list[str],
    *,
    namespace: str = "",
    use_sim_time: bool = False,
    calibration_file: str = "",
    composed: bool = False,
    camera_input: str = "driver",
    rviz_config: str = "",
) -> list[NodeSpec]:
    """The nodes of a pipeline launch.

    Separate: the bridge (when the cameras publish the driver's MarkerArrays), calib, the four
    stages and the visualizer. Composed: calib, the ``pipeline`` node (bridge and stages in one
    process) and the visualizer. ``rviz_config``, when given, adds RViz with that file.
    """
    if camera_input not in ("driver", "skeletons"):
        msg = f"input must be driver or skeletons, not {camera_input!r}"
        raise ConfigError(msg)
    namespace = "/" + namespace.strip("/") if namespace.strip("/") else ""
    remaps = _remappings(namespace, cameras)
    common = {"use_sim_time": use_sim_time}
    calib_node = f"{namespace}/calib"
    per_node: dict[str, dict[str, Any]] = {
        "azure_bridge": {"cameras": cameras},
        "calib": {"camera_names": cameras, "calibration_file": calibration_file},
        "tracker": {
            "cameras": cameras, "calibration_file": calibration_file, "calib_node": calib_node,
        },
        "merger": {"calibration_file": calibration_file, "calib_node": calib_node},
        "optimizer": {},
        "filter": {},
        "visualizer": {},
        "pipeline": {
            "cameras": cameras, "input": camera_input, "calibration_file": calibration_file,
            "calib_node": calib_node,
        },
    }  # fmt: skip
    if composed:
        names = ["calib", "pipeline", "visualizer"]
    else:
        names = [n for n in NODES if n != "azure_bridge" or camera_input == "driver"]
    specs = [NodeSpec(name, name, {**per_node[name], **common}, remaps) for name in names]
    if rviz_config:
        specs.append(NodeSpec("rviz2", "rviz2", dict(common), remaps, "rviz2", ["-d", rviz_config]))
    return specs


def share_file(*parts: str) -> str:
    """A file of the installed package's share folder (config/, rviz/), else of the source tree.

    The venv of ``make setup`` installs no share folder beyond package.xml: there the files
    are the checkout's.
    """
    source = Path(__file__).resolve().parent.parent.joinpath(*parts)
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = Path(get_package_share_directory("hiros")).joinpath(*parts)
    except (ImportError, LookupError, ValueError):
        return str(source)
    return str(installed if installed.exists() else source)

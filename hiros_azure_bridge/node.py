"""The ``azure_bridge`` and ``generic_bridge`` nodes: driver MarkerArrays -> SkeletonGroups.

Per camera: ``/<cam>/body_tracking_data`` (raw CDR) -> ``DriverBridge.update_bytes`` (decode,
convert) -> ``encode_group`` -> ``/<cam>/skeletons`` (raw CDR), in the camera's
frame and clock, nothing corrected (DESIGN.md). Topic names are templates in which
``{camera}`` is replaced by each name of the ``cameras`` parameter.

``generic_bridge`` is the same node under another name, meant to be configured for another
driver: by a parameter file (``--ros-args --params-file my_driver.yaml``) or by the
``description`` parameter naming a YAML file with the same keys, e.g. for a Kinect v2 driver::

    cameras: [kinect_left, kinect_right]
    input_topic: /{camera}/body_markers
    layout: kinect_v2            # or a layout YAML file
    id_scheme: body_major
    id_stride: 100
    position_scale: 0.001        # the driver publishes millimetres
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from visualization_msgs.msg import MarkerArray

from hiros_core.accounting import Merged
from hiros_core.codec import encode_group
from hiros_core.driver import DriverBridge, DriverBridgeParams, load_bridge_params, warm_up
from hiros_ros import HirosNode, run_node
from hiros_ros.node import camera_qos, pipeline_qos
from hiros_ros.params import parameter_specs

__all__ = ["BridgeNode", "BridgeNodeParams", "generic_main", "main"]


@dataclass
class BridgeNodeParams(DriverBridgeParams):
    """The bridge nodes' ROS parameters: the driver's id scheme plus cameras and topics.

    Attributes:
        cameras: camera names (topic namespaces).
        input_topic: driver topic template (``{camera}`` is replaced).
        output_topic: SkeletonGroup topic template.
        input_qos: ``sensor_data`` (best effort; also hears reliable drivers) or ``reliable``.
        description: optional YAML file whose values replace these parameters (generic
            drivers; see the module docstring).

    """

    cameras: list[str] = field(default_factory=lambda: ["k01"])
    input_topic: str = "/{camera}/body_tracking_data"
    output_topic: str = "/{camera}/skeletons"
    input_qos: str = "sensor_data"
    description: str = ""


class BridgeNode(HirosNode):
    """One DriverBridge, subscription and publisher per camera."""

    def __init__(self, node_name: str = "azure_bridge") -> None:
        super().__init__(node_name)
        self.declare_params(BridgeNodeParams, fixed=self._description())
        bridge_fields = {f.name for f in dataclasses.fields(DriverBridgeParams)}
        bridge_params = DriverBridgeParams(
            **{k: v for k, v in dataclasses.asdict(self.params).items() if k in bridge_fields}
        )
        warm_up()  # the compiled frame path, loaded before the first camera message
        self.bridges: dict[str, DriverBridge] = {}
        self._empty: dict[str, bool] = {}  # camera -> its last group had nobody
        for camera in self.params.cameras:
            source = self.params.input_topic.format(camera=camera)
            target = self.params.output_topic.format(camera=camera)
            self.bridges[camera] = DriverBridge(
                bridge_params, default_frame=f"{camera}_depth_camera_link"
            )
            publisher = self.create_raw_publisher(SkeletonGroupMsg, target, pipeline_qos())
            self.create_raw_subscription(
                MarkerArray,
                source,
                lambda data, c=camera, p=publisher: self.on_markers(c, p, data),
                camera_qos(self.params.input_qos),
            )
            self.get_logger().info(f"{source} -> DriverBridge({bridge_params.layout}) -> {target}")
        bridges = self.bridges.values()
        self.accounted = Merged([(f"{c}.", b) for c, b in self.bridges.items()], bridges)

    def _description(self) -> dict[str, Any]:
        """The values of the ``description`` file, which replace the parameters'.

        ``description`` is declared first, so that the others can be declared with them.
        """
        spec = next(s for s in parameter_specs(BridgeNodeParams) if s.name == "description")
        path = self.declare_parameter(spec.name, spec.default, spec.descriptor()).value
        if not path:
            return {}
        bridge, extra = load_bridge_params(path)
        node_fields = {"cameras", "input_topic", "output_topic", "input_qos"}
        values = dataclasses.asdict(bridge) | {k: v for k, v in extra.items() if k in node_fields}
        if "cameras" in values:
            values["cameras"] = [str(c) for c in values["cameras"]]
        return values

    def on_markers(self, camera: str, publisher: object, data: bytes) -> None:
        """Decode, convert, publish; a dropped message publishes nothing.

        An empty MarkerArray (the Azure driver's "nobody in view") goes out as an empty
        group, stamped at its arrival on the camera's clock (``DriverBridge.update``).
        """
        group = self.bridges[camera].update_bytes(data, self.get_clock().now().nanoseconds)
        if group is not None:
            self._empty[camera] = not group.skeletons
            self.publish_raw(publisher, encode_group(group))

    def status_notes(self) -> list[str]:
        """The cameras whose last frame showed nobody, and how many such frames there were."""
        empty = sorted(camera for camera, nobody in self._empty.items() if nobody)
        if not empty:
            return []
        frames = sum(self.bridges[camera].nobody_in_view for camera in self.bridges)
        return [f"nobody in view: {', '.join(empty)} ({frames} empty frame(s) so far)"]


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros azure_bridge``."""
    run_node(lambda: BridgeNode("azure_bridge"), args)


def generic_main(args: list[str] | None = None) -> None:
    """``ros2 run hiros generic_bridge``."""
    run_node(lambda: BridgeNode("generic_bridge"), args)

"""A node around one pipeline stage: SkeletonGroup in -> ``stage.update`` -> SkeletonGroup out."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg

from hiros_core.codec import decode_group, encode_group
from hiros_core.model import SkeletonGroup
from hiros_ros.node import HirosNode, camera_qos, pipeline_qos, run_node

__all__ = ["StageNode", "stage_main"]


class StageNode(HirosNode):
    """Subscribes ``input_topic`` (raw), runs the stage, publishes ``output_topic`` (raw).

    The topics and the input QoS are parameters of their own, beside the stage's dataclass
    fields. The stage accounts for the node's frames (``HirosNode.accounted``): what it
    processes, holds and drops is reported as the node's.
    """

    def __init__(
        self,
        node_name: str,
        params_type: type,
        make_stage: Callable[[Any], Any],
        *,
        input_topic: str,
        output_topic: str,
        input_qos: str = "reliable",
    ) -> None:
        super().__init__(node_name)
        self.params = self.declare_params(params_type)
        self.stage = make_stage(self.params)
        input_topic = self.declare_parameter("input_topic", input_topic).value
        output_topic = self.declare_parameter("output_topic", output_topic).value
        qos_kind = self.declare_parameter("input_qos", input_qos).value
        self.accounted = self.stage
        self.publisher = self.create_raw_publisher(SkeletonGroupMsg, output_topic, pipeline_qos())
        self.create_raw_subscription(
            SkeletonGroupMsg, input_topic, self.on_group, camera_qos(qos_kind)
        )
        self.get_logger().info(f"{input_topic} -> {type(self.stage).__name__} -> {output_topic}")

    def on_group(self, data: bytes) -> None:
        """Decode, update, publish; an empty result is published too (a frame with nobody)."""
        result = self.stage.update(decode_group(data))
        if isinstance(result, SkeletonGroup):
            self.publish_raw(self.publisher, encode_group(result))


def stage_main(
    node_name: str,
    params_type: type,
    make_stage: Callable[[Any], Any],
    *,
    input_topic: str,
    output_topic: str,
    args: list[str] | None = None,
) -> None:
    """``main()`` of a stage node executable."""
    run_node(
        lambda: StageNode(
            node_name, params_type, make_stage, input_topic=input_topic, output_topic=output_topic
        ),
        args,
    )

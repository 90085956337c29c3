"""A node around one pipeline stage: SkeletonGroup in -> ``stage.update`` -> SkeletonGroup out."""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg

from hiros_core.codec import decode_group, encode_group
from hiros_core.model import SkeletonGroup
from hiros_ros.node import HirosNode, camera_qos, pipeline_qos, run_node

__all__ = ["StageNode", "stage_main"]


class StageNode(HirosNode):
    """Subscribes ``input_topic`` (raw), runs the stage, publishes ``output_topic`` (raw).

    ``params_type`` is the node's dataclass: the stage's fields plus ``input_topic``,
    ``output_topic`` and ``input_qos``. A change of a ``live`` parameter reaches the stage
    through its ``set_params``. The stage accounts for the node's frames
    (``HirosNode.accounted``): what it processes, holds and drops is reported as the node's.
    """

    def __init__(
        self,
        node_name: str,
        params_type: type,
        make_stage: Callable[[Any], Any],
        *,
        live: Collection[str] = (),
    ) -> None:
        super().__init__(node_name)
        self.stage: Any = None
        params = self.declare_params(params_type, live=live, apply=self._apply)
        self.stage = make_stage(params)
        self.accounted = self.stage
        self.publisher = self.create_raw_publisher(
            SkeletonGroupMsg, params.output_topic, pipeline_qos()
        )
        self.create_raw_subscription(
            SkeletonGroupMsg, params.input_topic, self.on_group, camera_qos(params.input_qos)
        )
        self.get_logger().info(
            f"{params.input_topic} -> {type(self.stage).__name__} -> {params.output_topic}"
        )

    def _apply(self, params: Any) -> None:
        self.stage.set_params(params)

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
    live: Collection[str] = (),
    args: list[str] | None = None,
) -> None:
    """``main()`` of a stage node executable."""
    run_node(lambda: StageNode(node_name, params_type, make_stage, live=live), args)

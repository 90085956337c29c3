"""``visualizer`` node: SkeletonGroup topics -> ``<topic>/markers`` (MarkerArray)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from visualization_msgs.msg import MarkerArray

from hiros_core.codec import decode_group
from hiros_ros import HirosNode, run_node
from hiros_ros.node import pipeline_qos
from hiros_visualizer.markers import VisualizerParams, encode_skeleton_markers

LIVE = tuple(f.name for f in fields(VisualizerParams))
"""Drawing parameters are read for every message: all applied while the node runs."""


@dataclass
class VisualizerNodeParams(VisualizerParams):
    """Drawing parameters plus the topics to draw."""

    topics: list[str] = field(default_factory=lambda: ["/hiros/filter"])
    """SkeletonGroup topics to draw; each one's markers go out on <topic>/markers."""


class VisualizerNode(HirosNode):
    """For each topic, publishes its skeletons as markers on ``<topic>/markers``."""

    def __init__(self) -> None:
        super().__init__("visualizer")
        self.declare_params(VisualizerNodeParams, live=LIVE)
        for topic in self.params.topics:
            publisher = self.create_raw_publisher(MarkerArray, f"{topic}/markers", pipeline_qos())
            self.create_raw_subscription(
                SkeletonGroupMsg,
                topic,
                lambda data, topic=topic, publisher=publisher: self.on_group(
                    topic, publisher, data
                ),
                pipeline_qos(),
            )

    def on_group(self, topic: str, publisher: object, data: bytes) -> None:
        """Decode, draw, publish."""
        markers = encode_skeleton_markers(decode_group(data), topic.strip("/"), self.params)
        self.publish_raw(publisher, markers)


def main(args: list[str] | None = None) -> None:
    """Run the node until Ctrl-C."""
    run_node(VisualizerNode, args)

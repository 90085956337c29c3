"""``visualizer`` node: SkeletonGroup topics -> ``<topic>/markers`` (MarkerArray), optionally /tf.

<topic> (SkeletonGroup) -> Drawing.draw -> <topic>/markers: deletions of people who left,
    skeletons, velocity/acceleration arrows and joint angles where asked
                        -> joint_transforms -> /tf (a frame per joint, when joint_tf)
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from hiros_core.codec import decode_group
from hiros_ros import HirosNode, run_node
from hiros_ros.node import pipeline_qos
from hiros_ros.tf import tf_message
from hiros_visualizer.markers import VisualizerParams, warm_up
from hiros_visualizer.overlays import Drawing, OverlayParams, joint_transforms

LIVE = tuple(f.name for f in (*fields(VisualizerParams), *fields(OverlayParams)))
"""Drawing parameters are read for every message: all applied while the node runs."""


@dataclass
class VisualizerNodeParams(VisualizerParams, OverlayParams):
    """Drawing parameters plus the topics to draw."""

    topics: list[str] = field(default_factory=lambda: ["/hiros/filter"])
    """SkeletonGroup topics to draw; each one's markers go out on <topic>/markers."""
    joint_tf: bool = False
    """Also publish a TF frame per joint on /tf: <topic>/person_<id>/<joint name>."""


class VisualizerNode(HirosNode):
    """For each topic, publishes its skeletons as markers on ``<topic>/markers``."""

    def __init__(self) -> None:
        super().__init__("visualizer")
        self.declare_params(VisualizerNodeParams, live=LIVE)
        warm_up()  # the compiled drawing, before the first frame
        self._tf = self.create_publisher(TFMessage, "/tf", 100) if self.params.joint_tf else None
        for topic in self.params.topics:
            publisher = self.create_raw_publisher(MarkerArray, f"{topic}/markers", pipeline_qos())
            drawing = Drawing(topic.strip("/"), self.params, self.params)
            self.create_raw_subscription(
                SkeletonGroupMsg,
                topic,
                lambda data, publisher=publisher, drawing=drawing: self.on_group(
                    drawing, publisher, data
                ),
                pipeline_qos(),
            )

    def on_group(self, drawing: Drawing, publisher: object, data: bytes) -> None:
        """Decode, draw, publish (and the joints' frames)."""
        group = decode_group(data)
        drawing.params = drawing.overlays = self.params  # live changes apply from here
        for markers in drawing.draw(group):
            self.publish_raw(publisher, markers)
        if self._tf is not None and group.skeletons:
            prefix = f"{drawing.namespace}/"
            stamp = self.get_clock().now().to_msg()
            stamp.sec, stamp.nanosec = divmod(group.stamp_ns, 1_000_000_000)
            self._tf.publish(tf_message(joint_transforms(group, prefix), stamp))


def main(args: list[str] | None = None) -> None:
    """Run the node until Ctrl-C."""
    run_node(VisualizerNode, args)

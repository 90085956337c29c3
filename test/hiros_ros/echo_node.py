"""A hiros node for the two-process test: raw SkeletonGroup in, codec decode+encode, raw out."""

from __future__ import annotations

import sys

from hiros_skeleton_msgs.msg import SkeletonGroup

from hiros_core.codec import decode_group, encode_group
from hiros_ros import HirosNode, run_node
from hiros_ros.node import pipeline_qos


class EchoNode(HirosNode):
    """Answers every group on /hiros_test/in with the same group on /hiros_test/out."""

    def __init__(self) -> None:
        super().__init__("hiros_echo")
        self.out = self.create_raw_publisher(SkeletonGroup, "/hiros_test/out", pipeline_qos())
        self.create_raw_subscription(SkeletonGroup, "/hiros_test/in", self.on_group, pipeline_qos())

    def on_group(self, data: bytes) -> None:
        group = decode_group(data)
        group.frame_id = f"echo:{group.frame_id}"
        self.publish_raw(self.out, encode_group(group))


if __name__ == "__main__":
    run_node(EchoNode, sys.argv)

"""The composed pipeline node, built in the test's process: what it counts."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.ros


def test_frames_the_bridge_drops_are_counted_at_once(ros_context) -> None:
    """Drops of a frame the bridge dropped used to wait for the next good frame (and never
    showed while a camera sent only bad messages)."""
    from rclpy.serialization import serialize_message
    from visualization_msgs.msg import Marker, MarkerArray

    from hiros_pipeline.node import PipelineNode

    node = PipelineNode()
    delete_only = serialize_message(MarkerArray(markers=[Marker(action=Marker.DELETE)]))
    try:
        bridge = node._bridges["k01"]
        for _ in range(3):
            node.on_group(bridge.update_bytes(delete_only))
        # an empty array is nobody in view: processed, not dropped
        node.on_group(bridge.update_bytes(serialize_message(MarkerArray()), node._now()))
    finally:
        node.destroy_node()
    assert node.counters["dropped.bridge: nothing_to_add"] == 3
    assert bridge.nobody_in_view == 1
